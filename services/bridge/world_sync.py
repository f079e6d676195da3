"""Keeps the world's rows in step with the sim, writing once per distinct world.

The sim answers a query on ``pnav/sim/world`` and republishes the world every second or so.
:class:`WorldSync` asks once at start (and again every ``retry_s`` until a world is in),
listens to the republications, and upserts the rows
(:func:`~services.bridge.world_message.upsert_world`) only when the content differs from what
it last applied: a byte-identical payload is skipped without even decoding it, a re-encoded
but equal one after decoding. A refused payload is
remembered too, so a sim republishing a broken world costs a byte comparison per second.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable

import zenoh

from common import bus, log
from common.contract import keys
from common.db import Database
from common.lockstep import Ledger
from common.tasks import cancel_and_wait
from services.bridge.counters import Counters, RateLimitedLog
from services.bridge.sensor_payloads import MalformedMessage
from services.bridge.world_message import World, parse_world, upsert_world

logger = logging.getLogger("pnav.bridge.world")


class WorldSync:
    """Keeps the world's rows in step with the sim (see the module docstring)."""

    def __init__(
        self,
        session: zenoh.Session,
        db: Database,
        counters: Counters,
        *,
        retry_s: float,
        on_applied: Callable[[World], None],
        ledger: Ledger | None = None,
    ) -> None:
        """``ledger``: in a lockstep run, the world messages count on it once handled."""
        self.session = session
        self.ledger = ledger
        self.db = db
        self.counters = counters
        self.retry_s = retry_s
        self.on_applied = on_applied
        self.world: World | None = None
        self._applied_payload: bytes | None = None
        self._refused_payload: bytes | None = None
        self._latest: bytes | None = None
        self._wake = asyncio.Event()
        self._applying = False
        # called on the loop when an application ended (lockstep's reporter)
        self.on_idle: Callable[[], None] | None = None
        self._alerts = RateLimitedLog(logger, period_s=30.0)
        self._subscriber: zenoh.Subscriber[None] | None = None
        self._tasks: list[asyncio.Task[None]] = []

    def start(self) -> None:
        self._subscriber = bus.subscribe(
            self.session, keys.SIM_WORLD, self.offer, ledger=self.ledger
        )
        self._tasks = [
            asyncio.create_task(self._apply_loop(), name="world-apply"),
            asyncio.create_task(self._query_loop(), name="world-query"),
        ]

    async def close(self) -> None:
        if self._subscriber is not None:
            self._subscriber.undeclare()
            self._subscriber = None
        await cancel_and_wait(self._tasks)
        self._tasks = []

    def offer(self, key: str, payload: bytes) -> None:
        """A world payload arrived (publication or query reply); runs on the loop."""
        if payload == self._applied_payload:
            self.counters.worlds_unchanged += 1
            return
        if payload == self._refused_payload:
            self.counters.worlds_malformed += 1
            return
        self._latest = payload  # only the newest matters if several queue up
        self._wake.set()

    def query(self) -> None:
        """Ask the sim's queryable for its world; replies arrive through :meth:`offer`."""
        loop = asyncio.get_running_loop()

        def on_reply(reply: zenoh.Reply) -> None:  # on a Zenoh thread
            sample = reply.ok
            if sample is None:
                return
            with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
                loop.call_soon_threadsafe(
                    self.offer, str(sample.key_expr), sample.payload.to_bytes()
                )

        self.session.get(keys.SIM_WORLD, on_reply, timeout=max(self.retry_s, 1.0))

    async def _query_loop(self) -> None:
        while self.world is None:
            try:
                self.query()
            except Exception as exc:
                self._alerts.warning("query", "world query failed", error=exc)
            await asyncio.sleep(self.retry_s)

    def idle(self) -> bool:
        """A world is applied and no newer one is waiting or being written (lockstep: the
        bridge is not quiet before it has the world, so the sim holds until the robots,
        map and chargers are rows)."""
        return self.world is not None and not self._applying and not self._wake.is_set()

    async def _apply_loop(self) -> None:
        while True:
            await self._wake.wait()
            self._wake.clear()
            self._applying = True
            try:
                await self._apply_latest()
            finally:
                self._applying = False
            if self.on_idle is not None:
                self.on_idle()

    async def _apply_latest(self) -> None:
        payload, self._latest = self._latest, None
        if payload is None or payload == self._applied_payload:
            return
        try:
            world = parse_world(payload)
        except MalformedMessage as exc:
            self._refused_payload = payload
            self.counters.worlds_malformed += 1
            self._alerts.warning(exc.reason, "malformed world ignored", reason=exc.reason)
            return
        if world == self.world:
            self._applied_payload = payload
            self.counters.worlds_unchanged += 1
            return
        try:
            await upsert_world(self.db, world)
        except Exception as exc:
            # Postgres away or refusing: try again with the next republication
            self._alerts.warning("upsert", "world not written", error=exc)
            await asyncio.sleep(1.0)
            return
        self.world = world
        self._applied_payload = payload
        self.counters.worlds_applied += 1
        log.event(
            logger,
            logging.INFO,
            "world applied",
            world=world.name,
            robots=",".join(r.robot_id for r in world.robots),
            stations=len(world.stations),
            map=f"{world.map.width}x{world.map.height}@{world.map.resolution}",
        )
        self.on_applied(world)

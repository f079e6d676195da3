"""Fixtures for the bridge's contract tests: the bridge in-process, and a stand-in sim.

The stand-in sim is a plain Zenoh session publishing msgpack, exactly as a foreign client
would; nothing is mocked. Every test gets a fresh database and a fresh Zenoh router.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterable
from typing import Any

import asyncpg
import pytest
import zenoh

from common import bus
from common.config import ServiceConfig, ZenohSettings
from common.contract import keys
from common.runtime import Runtime
from pnav._testing import as_service_role, eventually
from services.bridge import Bridge, BridgeSettings
from tests.unit.bridge import payloads
from tests.unit.bridge.payloads import pack

# Zenoh needs a moment for a new subscription to reach the router.
SETTLE_S = 1.0  # generous: on a loaded 2-core machine declarations take a while
# Short periods keep the tests quick; the watchdog stays at the contract's 0.5 s (sim time).
FAST = BridgeSettings(command_period_s=0.05, prune_period_s=0.3, world_retry_s=0.5)


class Inbox:
    """Samples received on a key expression, decoded, in arrival order."""

    def __init__(self, session: zenoh.Session, key_expr: str) -> None:
        self.items: list[tuple[str, Any]] = []
        self._event = asyncio.Event()
        self._sub = bus.subscribe(session, key_expr, self._on)

    def _on(self, key: str, payload: bytes) -> None:
        self.items.append((key, bus.unpack(payload)))
        self._event.set()

    async def next(self, within: float = 5.0) -> tuple[str, Any]:
        """Wait for and remove the oldest unread sample."""
        deadline = time.monotonic() + within
        while not self.items:
            self._event.clear()
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise AssertionError("no sample arrived in time")
            try:
                await asyncio.wait_for(self._event.wait(), remaining)
            except TimeoutError:
                continue
        return self.items.pop(0)

    async def quiet(self, seconds: float) -> list[tuple[str, Any]]:
        """Wait ``seconds`` and return (and remove) whatever arrived meanwhile."""
        await asyncio.sleep(seconds)
        got, self.items = self.items, []
        return got

    def close(self) -> None:
        self._sub.undeclare()


class FakeSim:
    """Plays the sim's part on Zenoh: sensors, clock, world (published and queryable)."""

    def __init__(self, session: zenoh.Session) -> None:
        self.session = session
        self.notifier = bus.Notifier(session)
        self._queryable: Any = None
        self._inboxes: list[Inbox] = []

    def put(self, key: str, body: Any) -> None:
        payload = body if isinstance(body, bytes) else pack(body)
        # BLOCK: a test that floods must not lose samples in its own queues
        self.session.put(key, payload, congestion_control=zenoh.CongestionControl.BLOCK)

    def sensor(self, robot: str, topic: str, body: Any) -> None:
        self.put(keys.robot_key(robot, topic), body)

    def clock(self, stamp: float, rate: float = 0.0) -> None:
        """Publish sim time; rate 0 means the bridge's clock does not extrapolate."""
        self.put(keys.SIM_CLOCK, {"stamp": stamp, "rate": rate})

    def serve_world(self, world: dict[str, Any]) -> None:
        payload = pack(world)
        self._queryable = self.session.declare_queryable(
            keys.SIM_WORLD, lambda query: query.reply(keys.SIM_WORLD, payload)
        )

    def listen(self, key_expr: str) -> Inbox:
        inbox = Inbox(self.session, key_expr)
        self._inboxes.append(inbox)
        return inbox

    def close(self) -> None:
        for inbox in self._inboxes:
            inbox.close()
        if self._queryable is not None:
            self._queryable.undeclare()
        self.notifier.close()
        self.session.close()


@pytest.fixture
async def sim(zenoh_settings: ZenohSettings) -> AsyncIterator[FakeSim]:
    session = await asyncio.to_thread(bus.open_session, zenoh_settings)
    fake = FakeSim(session)
    try:
        yield fake
    finally:
        fake.close()


BridgeFactory = Callable[..., Awaitable[Bridge]]


@pytest.fixture
async def start_bridge(db_url: str, zenoh_settings: ZenohSettings) -> AsyncIterator[BridgeFactory]:
    """``await start_bridge(settings=FAST)``: a started in-process bridge, stopped at the end."""
    bridges: list[Bridge] = []
    role_url = await as_service_role(db_url, "bridge")  # exactly the bridge's grants

    async def start(settings: BridgeSettings = FAST) -> Bridge:
        config = ServiceConfig(
            service="bridge", database_url=role_url, zenoh=zenoh_settings, instance="test-bridge"
        )
        runtime = await Runtime.open(config)
        bridge = Bridge(runtime, settings)
        bridges.append(bridge)
        await bridge.start()
        await asyncio.sleep(SETTLE_S)
        return bridge

    try:
        yield start
    finally:
        for bridge in bridges:
            await bridge.stop()
            await bridge.runtime.close()


async def bridge_with_world(
    start_bridge: BridgeFactory,
    sim: FakeSim,
    world: dict[str, Any],
    settings: BridgeSettings = FAST,
) -> Bridge:
    """The sim serves ``world``; the bridge starts, asks for it and writes its rows."""
    sim.serve_world(world)
    await asyncio.sleep(SETTLE_S)
    bridge = await start_bridge(settings)
    await eventually(lambda: bridge.counters.worlds_applied >= 1, what="the world")
    return bridge


async def subscribers_known(bridge: Bridge, key_exprs: Iterable[str], within: float = 20) -> None:
    """Wait until the bridge's Zenoh session sees a matching subscriber on each key: until
    then the router has no route for the bridge's puts there, and a notification put is
    dropped (a fixed sleep was not enough on a loaded machine)."""
    publishers = [bridge.runtime.zenoh.declare_publisher(key) for key in key_exprs]
    try:
        await eventually(
            lambda: all(p.matching_status.matching for p in publishers),
            what="the subscribers known to the bridge",
            within=within,
        )
    finally:
        for publisher in publishers:
            publisher.undeclare()


async def count(conn: asyncpg.Connection, table: str) -> int:
    n: int = await conn.fetchval(f"SELECT count(*) FROM {table}")
    return n


async def command(
    conn: asyncpg.Connection,
    sim: FakeSim | None,
    linear: float,
    angular: float,
    *,
    robot: str = "r1",
    stamp: float = 10.0,
) -> int:
    """Insert a decision as the decision service would; notify unless ``sim`` is None."""
    row_id: int = await conn.fetchval(
        "INSERT INTO command2robot (robot_id, stamp, linear_mps, angular_rps, source, reason)"
        " VALUES ($1, $2, $3, $4, 'test', 'a test decision') RETURNING id",
        robot,
        stamp,
        linear,
        angular,
    )
    if sim is not None:
        sim.notifier.notify(keys.COMMAND2ROBOT, robot, row_id)
    return row_id


async def ready(
    start_bridge: BridgeFactory,
    sim: FakeSim,
    robots: tuple[str, ...] = ("r1",),
    settings: BridgeSettings = FAST,
) -> tuple[Bridge, Inbox]:
    """A bridge with a world, a sim clock at 10.0 s (not running on its own), a cmd_vel inbox."""
    cmd_vel = sim.listen(keys.robot_watch(keys.CMD_VEL))
    bridge = await bridge_with_world(start_bridge, sim, payloads.world(robots=robots), settings)
    sim.clock(10.0)
    await eventually(lambda: bridge.runtime.clock.now() == 10.0, what="the sim clock")
    return bridge, cmd_vel


def vel(body: dict[str, Any]) -> tuple[float, float, int | None]:
    return body["linear"], body["angular"], body["command_id"]

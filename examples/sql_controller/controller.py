"""The controller loop: wake on a notification (or every period), read, decide, write, notify.

No rule engine: one asyncio loop. Each tick reads, in one query, every robot this process
owns with its strategy and the ids of its newest scan and odometry; for a robot whose newest
scan is fresh and not yet used by an enabled behaviour, it reads the beams, runs the policy
(policy.py), writes the recommendations in one transaction and, after COMMIT, publishes
``pnav/db/command_recommendation/{robot}``.

Start-up order matters to whoever waits for us: the subscriptions and the first lease cycle
come first, the liveliness token ``pnav/alive/controller/{instance}`` last, so a token seen
means "ready to act". Shutdown is the reverse, and gives the robots back.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass

import asyncpg
import zenoh

from examples.sql_controller import store
from examples.sql_controller.environment import SERVICE, Settings
from examples.sql_controller.leases import Leases
from examples.sql_controller.policy import KNOWN, decide, param
from examples.sql_controller.zenoh_io import (
    SIM_CLOCK,
    SimClock,
    alive_key,
    notify_watch,
    on_any_sample,
    open_session,
    publish_change,
)

logger = logging.getLogger("sql_controller")

# A change in any of these may change what we should recommend now.
WATCHED = ("laser_scan", "active_strategy", "strategy", "robot")


@dataclass
class Counters:
    """What engine_stats shows for one behaviour (there are no rules: one row per source)."""

    decided: int = 0  # fresh scans it looked at
    acted: int = 0  # recommendations it wrote
    total_s: float = 0.0
    max_s: float = 0.0

    def timed(self, seconds: float) -> None:
        self.decided += 1
        self.total_s += seconds
        self.max_s = max(self.max_s, seconds)


class Controller:
    def __init__(
        self, settings: Settings, session: zenoh.Session, pool: asyncpg.Pool, leases: Leases | None
    ) -> None:
        self.settings = settings
        self.session = session
        self.pool = pool
        self.leases = leases
        self.clock = SimClock()
        self.used: dict[tuple[str, str], int] = {}  # (robot, source) -> newest scan used
        self.known: set[str] = set()  # robots whose `used` was loaded from the table
        self.unknown: set[str] = set()  # scenario names logged once as not ours
        self.counters = {name: Counters() for name in KNOWN}
        self.failing = False

    async def loop(self, stop: asyncio.Event, wake: asyncio.Event) -> None:
        last_stats = time.monotonic()
        while not stop.is_set():
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(self.settings.period_s):  # the fallback: a lost
                    await wake.wait()  # notification only delays us
            wake.clear()
            if stop.is_set():
                break
            try:
                await self.tick()
                if self.failing:
                    logger.info("database reachable again")
                self.failing = False
            except (OSError, asyncpg.PostgresError, asyncpg.InterfaceError) as exc:
                if not self.failing:  # once per outage, not 20 times a second
                    logger.warning("tick failed, retrying: %r", exc)
                self.failing = True
            if time.monotonic() - last_stats >= self.settings.stats_period_s:
                last_stats = time.monotonic()
                await self.publish_stats()

    async def tick(self) -> None:
        robots: Sequence[str] | None = None  # None: every robot (leases off)
        if self.leases is not None:
            owned = self.leases.owned()
            for robot in self.known - owned:  # another replica serves it now: forget it
                self.known.discard(robot)
                self.used = {k: v for k, v in self.used.items() if k[0] != robot}
            if not owned:
                return
            robots = sorted(owned)
        acting = self.leases.acting if self.leases is not None else asyncio.Lock()
        async with acting:
            for situation in await store.situations(self.pool, robots):
                await self.serve(situation)

    async def serve(self, now: store.Situation) -> None:
        robot = now.robot.robot_id
        enabled = [name for name in now.scenarios if name in KNOWN]
        for name in set(now.scenarios) - set(KNOWN) - self.unknown:
            self.unknown.add(name)
            logger.warning(
                "strategy %s names %r: not a scenario of this controller", now.strategy, name
            )
        sim_now = self.clock.now()
        if not enabled or now.scan_id is None or now.scan_stamp is None or sim_now is None:
            return  # IDLE, no scan yet, or no sim clock yet: nothing is fresh
        if robot not in self.known:  # new to us: what did the previous holder already use?
            for source, scan_id in (await store.last_used_scans(self.pool, robot, KNOWN)).items():
                self.used[(robot, source)] = scan_id
            self.known.add(robot)
        todo = [name for name in enabled if self.used.get((robot, name)) != now.scan_id]
        max_age = param(now.params, "scan_max_age_s", 0.5, high=3600.0)
        # abs(): our clock may trail the sim's by a few ms, so a new scan can look early
        if not todo or abs(sim_now - now.scan_stamp) > max_age:
            return
        scan = await store.scan(self.pool, now.scan_id)
        if scan is None:
            return
        started = time.perf_counter()
        advice = decide(scan, now.robot, now.speed_mps, now.params, todo)
        elapsed = time.perf_counter() - started
        for name in todo:
            self.counters[name].timed(elapsed)
        if advice:
            newest = await store.recommend(self.pool, now, scan, advice)
            publish_change(self.session, "command_recommendation", robot, newest)  # committed
            for a in advice:
                self.counters[a.source].acted += 1
                logger.debug(
                    "%s %s: %.2f m/s %.2f rad/s: %s", robot, a.source, a.linear, a.angular, a.reason
                )
        for name in todo:  # used, whether or not it had something to say
            self.used[(robot, name)] = scan.id

    async def publish_stats(self) -> None:
        rows = [
            (
                SERVICE,
                self.settings.instance,
                f"sql_controller.{name}",
                name,
                c.decided,
                c.decided,
                c.acted,
                0,
                c.total_s,
                c.max_s,
            )
            for name, c in self.counters.items()
            if c.decided
        ]
        try:
            await store.write_stats(self.pool, rows)
            if rows:
                publish_change(self.session, "engine_stats", None, None)
        except (OSError, asyncpg.PostgresError, asyncpg.InterfaceError):
            logger.warning("could not write engine_stats", exc_info=True)


async def open_pool(settings: Settings) -> asyncpg.Pool:
    """A pool for reads and writes; Postgres may still be starting: retry for a while."""
    deadline = time.monotonic() + settings.db_wait_s
    while True:
        try:
            pool: asyncpg.Pool = await asyncpg.create_pool(
                settings.database_url, min_size=1, max_size=settings.pool_max
            )
            return pool
        except (OSError, asyncpg.CannotConnectNowError):
            if time.monotonic() >= deadline:
                raise
            await asyncio.sleep(0.2)


async def run(settings: Settings, stop: asyncio.Event) -> None:
    """Run until ``stop`` is set; every resource is released in reverse order of opening."""
    loop = asyncio.get_running_loop()
    wake = asyncio.Event()
    stop_waiter = asyncio.create_task(stop.wait())
    stop_waiter.add_done_callback(lambda _task: wake.set())  # a signal ends the nap at once
    async with contextlib.AsyncExitStack() as stack:
        stack.callback(stop_waiter.cancel)
        # Zenoh's open blocks while it connects: keep the loop (and signals) free meanwhile.
        session = await asyncio.to_thread(open_session, settings)
        stack.push_async_callback(asyncio.to_thread, session.close)
        pool = await open_pool(settings)
        stack.push_async_callback(pool.close)
        leases = None
        if settings.leases:
            leases = Leases(settings, lambda r, i: publish_change(session, "robot_lease", r, i))
            await leases.start()
            stack.push_async_callback(leases.stop)
            lease_task = asyncio.create_task(leases.run(stop))
            stack.push_async_callback(_finish, lease_task, leases)
            # hints that it is worth revising ownership now rather than at the next period
            poke = on_any_sample(loop, leases.poke)
            stack.callback(
                session.liveliness().declare_subscriber(f"pnav/alive/{SERVICE}/*", poke).undeclare
            )
            stack.callback(session.declare_subscriber(notify_watch("robot"), poke).undeclare)
        controller = Controller(settings, session, pool, leases)
        stack.callback(session.declare_subscriber(SIM_CLOCK, controller.clock.on_sample).undeclare)
        for table in WATCHED:
            stack.callback(
                session.declare_subscriber(
                    notify_watch(table), on_any_sample(loop, wake.set)
                ).undeclare
            )
        stack.push_async_callback(controller.publish_stats)  # a last write, before the pool goes
        token = session.liveliness().declare_token(alive_key(SERVICE, settings.instance))
        stack.callback(token.undeclare)
        logger.info(
            "ready: instance %s, leases %s, owns %s",
            settings.instance,
            "on" if leases else "off",
            ",".join(sorted(leases.owned())) if leases else "every robot",
        )
        await controller.loop(stop, wake)
        logger.info("stopping")


async def _finish(task: asyncio.Task[None], leases: Leases) -> None:
    leases.poke()  # end its nap; it sees `stop` and returns after the cycle under way
    await task

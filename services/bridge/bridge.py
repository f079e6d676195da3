"""The bridge: the one service that talks to the robot (docs/ARCHITECTURE.md, the data path).

Wiring only; each concern lives in its own module:

- sensors: ``pnav/robot/*/{scan,odom,battery,collision}`` -> :mod:`.messages` (validate)
  -> :mod:`.writer` (batched INSERTs + notifications) -> :mod:`.acks` (a collision event's
  committed row acknowledged to the robot, which resends it until then). Zenoh callbacks
  only hand the bytes to the loop (``bus.subscribe``), so a slow INSERT never stalls
  Zenoh's threads;
- world: :mod:`.world_sync` and :mod:`.world` (robot, map and charging_station rows);
- commands: :mod:`.commands` (command2robot -> cmd_vel, clamp, :mod:`.watchdog`);
- housekeeping here: ``prune_sensor_rows()`` every ``prune_period_s``, the counters logged
  every ``stats_period_s``.

A malformed message is counted, logged (rate-limited) and dropped; nothing a publisher sends
can stop the bridge or reach the database.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import time
from pathlib import Path

import zenoh

from common import bus, lockstep, log
from common.bus import open_session
from common.config import ServiceConfig
from common.contract import keys
from common.errors import ConfigError
from common.robotlink import NATIVE, RobotLinkSettings
from common.runtime import Runtime, run_service
from common.tasks import cancel_and_wait
from common.trace import Tracer
from services.bridge.acks import CollisionAcks
from services.bridge.command_relay import CommandRelay
from services.bridge.counters import Counters, RateLimitedLog
from services.bridge.ros2clock import Ros2Clock
from services.bridge.ros2link import Ros2Link, native_topics
from services.bridge.ros2map import Ros2Map
from services.bridge.sensor_payloads import (
    UNKNOWN_ROBOT,
    LaserScan,
    MalformedMessage,
    Odometry,
    SensorRecord,
    parse_sensor,
)
from services.bridge.settings import BridgeSettings
from services.bridge.world_message import World
from services.bridge.world_sync import WorldSync
from services.bridge.writer import SensorWriter

logger = logging.getLogger("pnav.bridge")

SERVICE = "bridge"
# after an unknown robot's message, look at the robot table again at most this often
_ROBOT_RELOAD_S = 1.0


class Bridge:
    def __init__(
        self,
        runtime: Runtime,
        settings: BridgeSettings | None = None,
        link: RobotLinkSettings | None = None,
    ) -> None:
        self.runtime = runtime
        self.settings = settings or BridgeSettings()
        # the robot link: native (the sim's msgpack, default) or ROS 2 (ros2link.py)
        self.link_settings = link or RobotLinkSettings()
        if self.link_settings.link != NATIVE and runtime.ledger is not None:
            raise ConfigError("lockstep runs only on the native robot link")
        self.ros2: Ros2Link | None = None
        # the stack's clock in ROS time, for a ROS 2 robot with no pybullet sim (ros2clock.py)
        self.ros2_clock: Ros2Clock | None = None
        # the world's map from a ROS map server's /map, when the robot-link file asks
        self.ros2_map: Ros2Map | None = None
        self._ros2_session: zenoh.Session | None = None
        self.counters = Counters()
        # robot ids sensors may come from: the robot table, kept up to date
        # the known robots, each with its lidar's beam count (robot.lidar_beams): a scan
        # of another shape is malformed
        self.robots: dict[str, int] = {}
        db = runtime.database
        self.writer = SensorWriter(
            runtime.config.database_url,
            db.notifier,
            self.counters,
            max_pending=self.settings.max_pending_rows,
        )
        self.acks = CollisionAcks(runtime.zenoh, self.counters, runtime.ledger)
        self.writer.on_committed = self.acks.committed
        self.world = WorldSync(
            runtime.zenoh,
            db,
            self.counters,
            retry_s=self.settings.world_retry_s,
            on_applied=self._on_world,
            ledger=runtime.ledger,
        )
        self.commands = CommandRelay(
            runtime.zenoh,
            db.pool,
            runtime.clock,
            self.counters,
            self.settings,
            ledger=runtime.ledger,
        )
        self._malformed_log = RateLimitedLog(logger)
        self._subscribers: list[zenoh.Subscriber[None]] = []
        self._tasks: list[asyncio.Task[None]] = []
        self._last_reload = 0.0
        self._reload: asyncio.Task[None] | None = None
        self._reload_again = False
        self._stopped = False

    # -- lifecycle -----------------------------------------------------------------------
    async def start(self) -> None:
        session, ledger = self.runtime.zenoh, self.runtime.ledger
        if self.link_settings.link != NATIVE:
            self._start_ros2()
        await self._load_robots()
        await self.writer.start()
        for topic in native_topics(self.link_settings.link):
            handler = functools.partial(self._on_sensor, topic)
            self._subscribers.append(
                bus.subscribe(session, keys.robot_watch(topic), handler, ledger=ledger)
            )
        self._subscribers.append(
            bus.subscribe(
                session,
                keys.notify_watch(keys.ROBOT),
                self._on_robot_notification,
                ledger=ledger,
            )
        )
        self.world.start()
        await self.commands.start()
        self._tasks = [
            asyncio.create_task(self._prune_loop(), name="prune"),
            asyncio.create_task(self._stats_loop(), name="bridge-stats"),
        ]
        if ledger is not None:
            self._tasks.append(asyncio.create_task(self._report_quiet(ledger), name="lockstep"))
        log.event(
            logger,
            logging.INFO,
            "bridge started",
            robot_link=self.link_settings.link,
            robots=",".join(sorted(self.robots)),
            watchdog_s=self.settings.watchdog_s,
            safety="on" if self.settings.safety.enabled else "off",
        )

    async def stop(self) -> None:
        """Stop listening, send every robot a zero velocity, write what is queued."""
        if self._stopped:
            return
        self._stopped = True
        for subscriber in self._subscribers:
            with contextlib.suppress(Exception):
                subscriber.undeclare()
        self._subscribers.clear()
        await cancel_and_wait([*self._tasks, *([self._reload] if self._reload else [])])
        self._tasks.clear()
        await self.world.close()
        # the robots' stop first: it must not wait behind a slow Postgres draining sensor rows
        await self.commands.close(self.robots)
        if self.ros2_clock is not None:
            await self.ros2_clock.close()
        if self.ros2_map is not None:
            await self.ros2_map.close()
        if self.ros2 is not None:
            self.ros2.close()
        if self._ros2_session is not None:
            with contextlib.suppress(Exception):
                self._ros2_session.close()
        await self.writer.close()
        log.event(logger, logging.INFO, "bridge counters", **self.counters.snapshot())

    async def run(self, stop: asyncio.Event) -> None:
        # a stop asked while starting ends the start: a start can wait for a Postgres or a
        # router that is gone (its launcher killed), and would wait for ever
        starting = asyncio.ensure_future(self.start())
        asked = asyncio.ensure_future(stop.wait())
        try:
            await asyncio.wait({starting, asked}, return_when=asyncio.FIRST_COMPLETED)
            if not starting.done():
                await cancel_and_wait([starting])
                return
            starting.result()
            await stop.wait()
        finally:
            asked.cancel()
            await self.stop()

    # -- sensors -------------------------------------------------------------------------
    def _on_sensor(self, topic: str, key: str, payload: bytes) -> None:
        self.counters.messages_in[topic] += 1
        try:
            record = parse_sensor(topic, key, payload, self.robots)
        except MalformedMessage as exc:
            self._malformed(topic, exc.reason, exc.detail, key)
            if exc.reason == UNKNOWN_ROBOT:
                self._reload_robots_soon()
            return
        except Exception as exc:  # a bug in validation: still never let it through
            self._malformed(topic, "internal_error", repr(exc), key)
            return
        self._accept(record)

    def _accept(self, record: SensorRecord) -> None:
        """A valid reading from either link: into the safety layer and the writer."""
        if isinstance(record, LaserScan):
            self.commands.safety.scan(record)  # before any command decided from it comes
        elif isinstance(record, Odometry):  # where the robot is, for the speed zones
            self.commands.safety.zones.pose(record.robot_id, record.stamp, record.x, record.y)
        self.writer.add(record)

    def _start_ros2(self) -> None:
        """The ROS 2 link's own session (the rmw_zenoh router's, or ours as the bridge)."""
        zenoh_settings = self.link_settings.session_settings(self.runtime.config.zenoh)
        self._ros2_session = open_session(zenoh_settings)
        self.ros2 = Ros2Link(
            self.link_settings,
            self._ros2_session,
            self.counters,
            self._accept,
            self._malformed,
            Tracer(Path(self.settings.trace)) if self.settings.trace else None,
        )
        self.ros2.start()
        self.commands.send_out = self.ros2.send_cmd_vel
        if self.link_settings.bridge_clock:
            self.ros2_clock = Ros2Clock(
                self.runtime.zenoh,
                self.ros2.node,
                self.link_settings.use_sim_time,
                self._malformed,
            )
            self.ros2_clock.start()
        if self.link_settings.map_topic:
            self.ros2_map = Ros2Map(
                self.ros2.node,
                self.runtime.database,
                self.link_settings.map_topic,
                self._malformed,
            )
            self.ros2_map.start()

    def _malformed(self, topic: str, reason: str, detail: str, key: str) -> None:
        self.counters.malformed[(topic, reason)] += 1
        self._malformed_log.warning(
            (topic, reason),
            "malformed message dropped",
            topic=topic,
            reason=reason,
            detail=detail[:200],
            key=key[:120],
        )

    # -- robots --------------------------------------------------------------------------
    def _on_world(self, world: World) -> None:
        self.robots = self.robots | {r.robot_id: r.lidar_beams for r in world.robots}
        if self.ros2 is not None:
            self.ros2.ensure(self.robots)
        if self.ros2_map is not None:
            self.ros2_map.world_applied(world.name)
        # a robot-table read under way may have started before the world's rows were in
        self._reload_again = self._reload is not None and not self._reload.done()

    def _on_robot_notification(self, key: str, payload: bytes) -> None:
        self.commands.robots_changed()
        self._reload_robots_soon(force=True)

    def _reload_robots_soon(self, *, force: bool = False) -> None:
        if self._reload is not None and not self._reload.done():
            # a read under way may predate the change that asked for this one: read again
            # when it is done, or its stale set would stand
            self._reload_again = self._reload_again or force
            return
        if not force and time.monotonic() - self._last_reload < _ROBOT_RELOAD_S:
            return
        self._reload = asyncio.create_task(self._load_robots_safely(), name="robots")

    async def _load_robots(self) -> None:
        self._last_reload = time.monotonic()
        async with self.runtime.database.pool.acquire() as conn:
            rows = await conn.fetch(f"SELECT robot_id, lidar_beams FROM {keys.ROBOT}")
        self.robots = {r[0]: r[1] for r in rows}
        if self.ros2 is not None:
            self.ros2.ensure(self.robots)

    async def _load_robots_safely(self) -> None:
        again = True
        while again:
            self._reload_again = False
            try:
                await self._load_robots()
            except Exception as exc:
                self._malformed_log.warning("robots", "robot table read failed", error=exc)
            again = self._reload_again

    # -- lockstep --------------------------------------------------------------------------
    def quiet(self) -> bool:
        """The world is applied; every sensor message handed over is written and notified,
        every command notification read and relayed; no robot reload under way."""
        reload = self._reload
        return (
            self.world.idle()
            and self.writer.idle()
            and self.commands.idle()
            and (reload is None or reload.done())
        )

    async def _report_quiet(self, ledger: lockstep.Ledger) -> None:
        """Report the bridge quiet (common.lockstep) whenever it is, after every counted
        message; the watchdog runs here first, on the sim time a clock message moved."""
        poke = asyncio.Event()
        loop = asyncio.get_running_loop()

        def wake() -> None:
            try:
                loop.call_soon_threadsafe(poke.set)
            except RuntimeError:
                pass  # loop closed: shutting down

        ledger.listener = wake
        self.writer.on_idle = self.commands.on_idle = self.world.on_idle = poke.set
        while True:
            poke.clear()
            mark = ledger.mark()
            self.commands.check_watchdog()
            if self.quiet():
                ledger.report_if_settled(mark)
            elif self._reload is not None and not self._reload.done():
                self._reload.add_done_callback(lambda _task: poke.set())
            await poke.wait()

    # -- housekeeping --------------------------------------------------------------------
    async def prune(self) -> int:
        """Run ``prune_sensor_rows()`` once; return the rows it deleted."""
        async with self.runtime.database.pool.acquire() as conn:
            deleted: int = await conn.fetchval("SELECT prune_sensor_rows()")
        self.counters.rows_pruned += deleted
        return deleted

    async def _prune_loop(self) -> None:
        while True:
            await asyncio.sleep(self.settings.prune_period_s)
            try:
                deleted = await self.prune()
            except Exception as exc:
                self._malformed_log.warning("prune", "prune_sensor_rows failed", error=exc)
                continue
            if deleted:
                log.event(logger, logging.DEBUG, "sensor rows pruned", deleted=deleted)

    async def _stats_loop(self) -> None:
        while True:
            await asyncio.sleep(self.settings.stats_period_s)
            log.event(logger, logging.INFO, "bridge counters", **self.counters.snapshot())


async def serve(
    config: ServiceConfig, stop: asyncio.Event, session: zenoh.Session | None = None
) -> None:
    """Run until ``stop`` is set; ``session``: a host's shared Zenoh session (pnav.run.host)."""
    settings = BridgeSettings.from_env()
    link = RobotLinkSettings.from_env()
    runtime = await Runtime.open(config, session=session)
    try:
        await Bridge(runtime, settings, link).run(stop)
    finally:
        await runtime.close()


def main(argv: list[str] | None = None) -> int:
    return run_service(SERVICE, serve, argv)

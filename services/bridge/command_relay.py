"""command2robot -> ``pnav/robot/{robot}/cmd_vel``: the newest decision, clamped, watched.

A command2robot notification that carries the row's image (CONTRACT.md, "Row images"), with
no notification lost before it on its key (``common.freshness.Sequences``), is sent at once,
on the notification's own loop turn, with the robot's limits from :class:`RobotLimits`: no
query. Otherwise (no image, an image without the columns the relay needs, a gap, limits not
known fresh), and every ``command_period_s`` of wall time in case a notification was lost,
the relay reads the newest row of the robots concerned, joined with the robot's limits.
Either way it publishes each row it has not sent yet, clamped to
``max_linear_mps``/``max_angular_rps`` (NaN becomes 0: a NaN reaching the motors is never
what the decision meant). Every row sent feeds the :class:`Watchdog`; a robot whose command
stream goes quiet for ``watchdog_s`` of sim time is sent one zero velocity
(``command_id`` nil), and every known robot is sent one on shutdown.

An image is first held to command2robot's rules and the ids the table can hold (command_images.py):
one that fails is counted, logged, and the table read instead: a forgery moves no robot.

At start-up the newest rows already in the table are not replayed blindly: a row written
before this bridge started may be minutes old, and driving a robot on it would be a
surprise. Only a row whose ``stamp`` is within ``watchdog_s`` of the current sim time counts.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Iterable

import asyncpg
import zenoh

from common import bus, lockstep, log
from common.clock import SimClock
from common.contract import keys
from common.contract.limits import clamp
from common.tasks import cancel_and_wait
from services.bridge.command_images import CommandImages
from services.bridge.command_row import NEWEST, NEWEST_OF, Command
from services.bridge.counters import Counters, RateLimitedLog
from services.bridge.notes import SafetyNotes
from services.bridge.robot_limits import RobotLimits
from services.bridge.safety import LIMITED, STOPPED, UNCHECKED, SafetyLayer, Verdict
from services.bridge.settings import BridgeSettings
from services.bridge.watchdog import Watchdog

logger = logging.getLogger("pnav.bridge.commands")


class CommandRelay:
    def __init__(
        self,
        session: zenoh.Session,
        pool: asyncpg.Pool,
        clock: SimClock,
        counters: Counters,
        settings: BridgeSettings,
        *,
        ledger: lockstep.Ledger | None = None,
    ) -> None:
        """``ledger``: in a lockstep run, the commands sent count on it, the notifications
        received too, and the watchdog runs when the bridge's reporter says, on sim-clock
        messages."""
        self.session = session
        self.pool = pool
        self.clock = clock
        self.counters = counters
        self.settings = settings
        self.watchdog = Watchdog(settings.watchdog_s)
        self.last_sent: dict[str, int] = {}  # newest command2robot id handled, per robot
        self._stopped: set[str] = set()  # robots the watchdog stopped
        self._wake = asyncio.Event()
        self._polling = False
        # called on the loop when a read of command2robot ended (lockstep's reporter)
        self.on_idle: Callable[[], None] | None = None
        self.ledger = ledger
        self._want_all = False
        self._wanted: set[str] = set()
        self.limits = RobotLimits()
        # the newest scan per robot (the bridge hands them over) and what the layer did
        self.safety = SafetyLayer(settings.safety)
        self.notes = SafetyNotes(pool)
        self.images = CommandImages(logger, counters.images_refused)
        self._alerts = RateLimitedLog(logger)
        self._subscriber: zenoh.Subscriber[None] | None = None
        self._subscriber_zones: zenoh.Subscriber[None] | None = None
        self._tasks: list[asyncio.Task[None]] = []
        # another robot link's sender (the ROS 2 link): (robot, stamp, linear, angular,
        # reliable, command_id); None: the native cmd_vel below
        self.send_out: Callable[[str, float, float, float, bool, int | None], None] | None = None

    async def start(self) -> None:
        # Subscribe before the first read, so a command written in between is not missed.
        self._subscriber = bus.subscribe(
            self.session,
            keys.notify_watch(keys.COMMAND2ROBOT),
            self._on_notification,
            ledger=self.ledger,
        )
        self._subscriber_zones = bus.subscribe(
            self.session, keys.notify_watch(keys.ZONE), self._on_zones, ledger=self.ledger
        )
        async with self.pool.acquire() as conn:
            await self.limits.read(conn)
            await self.safety.zones.read(conn)
            rows = await conn.fetch(NEWEST)
        self.counters.command_reads += 1
        self.notes.start()
        for row in rows:
            self.images.read(row["id"])
            self._consider(Command.from_row(row), at_start=True)
        self._tasks = [
            asyncio.create_task(self._poller(), name="command-poller"),
            asyncio.create_task(self._ticker(), name="command-ticker"),
        ]

    async def close(self, robots: Iterable[str] = ()) -> None:
        """Stop listening, then send every robot (``robots`` and those commanded) a zero."""
        for subscriber in (self._subscriber, self._subscriber_zones):
            if subscriber is not None:
                subscriber.undeclare()
        self._subscriber = self._subscriber_zones = None
        await cancel_and_wait(self._tasks)
        self._tasks = []
        targets = sorted(set(robots) | set(self.last_sent))
        for robot in targets:
            self._send(robot, 0.0, 0.0, None, reliable=True)
            self.safety.sent_stop(robot)
            self.counters.shutdown_stops += 1
        if targets:
            log.event(logger, logging.INFO, "stop sent on shutdown", robots=",".join(targets))
        await self.notes.close()

    # -- reading -------------------------------------------------------------------------
    def robots_changed(self) -> None:
        """A robot notification: read the robots' limits again before trusting them."""
        self.limits.changed()
        self._wake.set()

    def _on_zones(self, key: str, payload: bytes) -> None:
        """A zone notification: the speed zones are read before the next command's verdict
        can count on them (the poller reads them; a command meanwhile meets the old ones)."""
        self.safety.zones.changed()
        self._wake.set()

    def _on_notification(self, key: str, payload: bytes) -> None:
        try:
            note = bus.Notification.decode(key, payload)
        except ValueError:
            return  # not ours to judge; the periodic read still covers the table
        robot = note.robot
        if robot is None:
            self._want_all = True
            self._wake.set()
            return
        # every notification counts toward the numbering, even one already acted on
        gap = self.images.guard.gap(note, key)
        self.counters.command_notes_lost = self.images.guard.lost
        if not gap and note.id is not None and note.id <= self.last_sent.get(robot, 0):
            return  # already sent
        command = None if gap else self._from_image(robot, note)
        if command is None:
            self._wanted.add(robot)
            self._wake.set()
            return
        self.counters.commands_from_images += 1
        self.images.sent(robot, command.id)
        self._consider(command)

    def _from_image(self, robot: str, note: bus.Notification) -> Command | None:
        image = self.images.image(note)
        if image is None:
            return None
        limits = self.limits.of(robot)
        return None if limits is None else Command.from_image(robot, image, limits)

    async def _poller(self) -> None:
        while True:
            await self._wake.wait()
            self._wake.clear()
            wanted = None if self._want_all else list(self._wanted)
            self._want_all = False
            self._wanted.clear()
            self._polling = True
            try:
                started = time.monotonic()
                rows = await self._read(wanted)
                for row in rows:
                    self.images.read(row["id"])
                    command = Command.from_row(row)
                    if self.images.phantom(command.robot_id, command.id, started):
                        # sent from a forged image: the table's row is the robot's last
                        current = self._current(command)
                        self.last_sent[command.robot_id] = command.id - int(current)
                    limits = (
                        command.max_linear,
                        command.max_angular,
                        command.footprint,
                        command.max_accel,
                    )
                    self.limits.check(command.robot_id, limits)
                    self._consider(command)
            except Exception as exc:  # Postgres away: the watchdog still stops the robots
                self._alerts.warning("read", "command2robot read failed", error=exc)
                await asyncio.sleep(0.1)
            finally:
                self._polling = False
            if self.on_idle is not None:
                self.on_idle()

    async def _read(self, wanted: list[str] | None) -> list[asyncpg.Record]:
        """The limits if stale, and the newest command of ``wanted`` (None: every robot)."""
        async with self.pool.acquire() as conn:
            if self.limits.stale():
                await self.limits.read(conn)
            if self.safety.zones.due():
                await self.safety.zones.read(conn)
            if wanted == []:
                return []  # woken for the limits alone
            self.counters.command_reads += 1
            if wanted is None:
                return list(await conn.fetch(NEWEST))
            return list(await conn.fetch(NEWEST_OF, wanted))

    def idle(self) -> bool:
        """No read of command2robot under way or asked for."""
        return not (self._polling or self._wake.is_set())

    def check_watchdog(self) -> None:
        """Stop every robot whose command stream went quiet (sim time)."""
        if self.clock.started:
            for robot, age in self.watchdog.expired(self.clock.now()):
                self._watchdog_stop(robot, age)

    async def _ticker(self) -> None:
        """Runs the watchdog every tick and asks for a full re-read every period."""
        tick = min(self.settings.watchdog_tick_s, self.settings.command_period_s)
        next_read = time.monotonic() + self.settings.command_period_s
        while True:
            await asyncio.sleep(tick)
            if self.ledger is None:
                self.check_watchdog()
            now = time.monotonic()
            if now >= next_read:
                next_read = now + self.settings.command_period_s
                self._want_all = True
                self._wake.set()

    # -- sending -------------------------------------------------------------------------
    def _consider(self, cmd: Command, *, at_start: bool = False) -> None:
        robot = cmd.robot_id
        if cmd.id <= self.last_sent.get(robot, 0):
            return
        self.last_sent[robot] = cmd.id
        if at_start and not self._current(cmd):
            log.event(
                logger,
                logging.INFO,
                "stale command at start-up not sent",
                robot=robot,
                command_id=cmd.id,
                stamp=cmd.stamp,
                sim_now=self.clock.now(),
            )
            return
        angular = clamp(cmd.angular, cmd.max_angular)
        now = self.clock.now() if self.clock.started else None
        linear = clamp(cmd.linear, cmd.max_linear)
        verdict = self.safety.judge(robot, linear, cmd.footprint, now, cmd.max_accel, angular)
        angular = angular if verdict.angular is None else verdict.angular
        try:
            self._send(robot, verdict.linear, angular, cmd.id, decided_stamp=cmd.stamp)
        except Exception as exc:  # Zenoh closing
            self._alerts.warning("send", "cmd_vel publish failed", error=exc)
            return
        self.counters.commands_out += 1
        if verdict.noted:  # after the send: the note never delays the cmd_vel
            self._noted(cmd, verdict, angular)
        self.watchdog.feed(robot, self.clock.now() if self.clock.started else None)
        if robot in self._stopped:
            self._stopped.discard(robot)
            log.event(logger, logging.INFO, "commands resumed", robot=robot, command_id=cmd.id)

    def _noted(self, cmd: Command, verdict: Verdict, angular: float) -> None:
        self.notes.add(cmd.id, verdict.reason, verdict.linear, angular)
        if verdict.outcome == STOPPED:
            self.counters.safety_stopped += 1
        elif verdict.outcome == LIMITED:
            self.counters.safety_limited += 1
        elif verdict.outcome == UNCHECKED:
            self.counters.safety_unchecked += 1
        if verdict.zone is not None:
            self.counters.safety_zone_capped += 1
        level = logging.INFO if verdict.outcome == UNCHECKED else logging.WARNING
        # keyed by outcome alone: a small set, whatever the robot ids
        self._alerts.log(
            level,
            ("safety", verdict.outcome),
            "safety layer: command " + verdict.outcome,
            robot=cmd.robot_id,
            command_id=cmd.id,
            decided_mps=cmd.linear,
            sent_mps=round(verdict.linear, 4),
            why=verdict.reason,
        )

    def _current(self, cmd: Command) -> bool:
        return self.clock.started and abs(self.clock.now() - cmd.stamp) <= self.watchdog.timeout_s

    def _watchdog_stop(self, robot: str, age: float) -> None:
        try:
            self._send(robot, 0.0, 0.0, None, reliable=True)
        except Exception as exc:
            self._alerts.warning("send", "cmd_vel publish failed", error=exc)
            return
        self._stopped.add(robot)
        self.safety.sent_stop(robot)
        self.counters.watchdog_stops += 1
        log.event(
            logger,
            logging.WARNING,
            "watchdog stop: no fresh command",
            robot=robot,
            silent_sim_s=round(age, 3),
            last_command_id=self.last_sent.get(robot),
        )

    def _send(
        self,
        robot: str,
        linear: float,
        angular: float,
        command_id: int | None,
        *,
        decided_stamp: float | None = None,
        reliable: bool = False,
    ) -> None:
        if self.send_out is not None:
            self.send_out(robot, self.clock.now(), linear, angular, reliable, command_id)
            return
        if self.ledger is not None:
            self.ledger.sent_on(keys.robot_key(robot, keys.CMD_VEL))
        payload = bus.pack(
            {
                "stamp": self.clock.now(),
                "linear": linear,
                "angular": angular,
                "command_id": command_id,
                "decided_stamp": decided_stamp,
            }
        )
        # Session puts, not a declared publisher per robot: a client's freshly declared
        # publisher drops its first puts until the router has answered its interest in
        # subscribers, which would lose a robot's first command (common/bus.py, Notifier).
        # A stop is sent once: it waits for a full queue rather than be dropped; a moving
        # command is superseded 50 ms later, so it is dropped under congestion.
        self.session.put(
            keys.robot_key(robot, keys.CMD_VEL),
            payload,
            congestion_control=(
                zenoh.CongestionControl.BLOCK if reliable else zenoh.CongestionControl.DROP
            ),
            priority=zenoh.Priority.REAL_TIME,
            express=True,
        )

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

An image is first held to command2robot's rules and the ids the table can hold (images.py):
one that fails is counted, logged, and the table read instead: a forgery moves no robot.

At start-up the newest rows already in the table are not replayed blindly: a row written
before this bridge started may be minutes old, and driving a robot on it would be a
surprise. Only a row whose ``stamp`` is within ``watchdog_s`` of the current sim time counts.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import asyncpg
import zenoh

from common import bus, lockstep, log
from common.clock import SimClock
from common.contract import keys
from common.footprint import Footprint
from common.freshness import Sequences
from common.tasks import cancel_and_wait
from services.bridge.counters import Counters, RateLimitedLog
from services.bridge.images import CommandImages
from services.bridge.limits import Limits, RobotLimits, limits_of
from services.bridge.notes import SafetyNotes
from services.bridge.safety import LIMITED, STOPPED, UNCHECKED, SafetyLayer, Verdict
from services.bridge.settings import BridgeSettings
from services.bridge.watchdog import Watchdog

logger = logging.getLogger("pnav.bridge.commands")

# LATERAL + LIMIT 1 walks the (robot_id, id DESC) index once per robot: the cost stays flat
# however long command2robot grows (it is not a pruned sensor table).
_NEWEST = f"""
SELECT r.robot_id, c.id, c.stamp, c.linear_mps, c.angular_rps,
       r.max_linear_mps, r.max_angular_rps, r.footprint_radius_m, r.footprint_polygon,
       r.max_linear_accel_mps2
FROM {keys.ROBOT} r
CROSS JOIN LATERAL (
    SELECT id, stamp, linear_mps, angular_rps FROM {keys.COMMAND2ROBOT} c
    WHERE c.robot_id = r.robot_id ORDER BY c.id DESC LIMIT 1
) c"""
_NEWEST_OF = _NEWEST + "\nWHERE r.robot_id = ANY($1::text[])"


def clamp(value: float, limit: float) -> float:
    """``value`` limited to [-limit, limit]; NaN (or a NaN/negative limit) gives 0."""
    if not limit >= 0:
        limit = 0.0
    if math.isnan(value):
        return 0.0
    result = max(-limit, min(limit, value))
    return result if math.isfinite(result) else 0.0


@dataclass(frozen=True, slots=True)
class Command:
    robot_id: str
    id: int
    stamp: float
    linear: float
    angular: float
    max_linear: float
    max_angular: float
    footprint: Footprint  # its polygon, or the disc of its radius
    max_accel: float  # the robot's linear acceleration limit: it brakes no harder

    @classmethod
    def from_row(cls, row: asyncpg.Record) -> Command:
        values = tuple(row)
        max_linear, max_angular, footprint, max_accel = limits_of(values[5:])
        robot, row_id, stamp, linear, angular = values[:5]
        return cls(
            robot, row_id, stamp, linear, angular, max_linear, max_angular, footprint, max_accel
        )

    @classmethod
    def from_image(cls, robot: str, image: Mapping[str, Any], limits: Limits) -> Command | None:
        """The command of a command2robot image, or None if the image lacks a column the
        relay needs (or has a wrong type in it, or names another robot)."""
        row_id = image.get("id")
        if type(row_id) is not int or image.get("robot_id") != robot:
            return None
        values: list[float] = []
        for column in ("stamp", "linear_mps", "angular_rps"):
            value = image.get(column)
            if not isinstance(value, float | int) or isinstance(value, bool):
                return None  # absent, or not a number
            values.append(float(value))
        stamp, linear, angular = values
        return cls(robot, row_id, stamp, linear, angular, *limits)


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
        self._sequences = Sequences()
        self.images = CommandImages(logger, counters.images_refused)
        self._alerts = RateLimitedLog(logger)
        self._subscriber: zenoh.Subscriber[None] | None = None
        self._tasks: list[asyncio.Task[None]] = []
        # another robot link's sender (the ROS 2 link): (robot, stamp, linear, angular,
        # reliable); None: the native cmd_vel below
        self.send_out: Callable[[str, float, float, float, bool], None] | None = None

    async def start(self) -> None:
        # Subscribe before the first read, so a command written in between is not missed.
        self._subscriber = bus.subscribe(
            self.session,
            keys.notify_watch(keys.COMMAND2ROBOT),
            self._on_notification,
            ledger=self.ledger,
        )
        async with self.pool.acquire() as conn:
            await self.limits.read(conn)
            rows = await conn.fetch(_NEWEST)
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
        if self._subscriber is not None:
            self._subscriber.undeclare()
            self._subscriber = None
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
        gap = self._sequences.gap(key, note.src, note.seq)
        self.counters.command_notes_lost = self._sequences.lost
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
            if wanted == []:
                return []  # woken for the limits alone
            self.counters.command_reads += 1
            if wanted is None:
                return list(await conn.fetch(_NEWEST))
            return list(await conn.fetch(_NEWEST_OF, wanted))

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
            self.send_out(robot, self.clock.now(), linear, angular, reliable)
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

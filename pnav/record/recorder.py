"""The recorder: change notifications in, contract rows read, Foxglove messages out to MCAP.

It wakes on every notification of a recorded table (and every ``period_s`` anyway, so a lost
notification only delays a row), reads the rows newer than the last it recorded, and logs
each as the messages of pnav/record/topics.py with its sim time as log time. Closing it
finishes the MCAP (its summary and index): the process does it on SIGINT and SIGTERM.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import asyncpg
import foxglove
from foxglove import channels as fc
from foxglove.messages import LogLevel

from common import bus
from common.clock import SimClock
from common.contract import keys
from pnav.record import topics
from pnav.record.source import APPENDED, BATCH, RecordSource, as_dict

log = logging.getLogger("pnav.record")

# tables whose rows change in place: new rows and those notified are read again
CHANGING = (keys.GOAL, keys.USER_COMMAND, keys.SYSTEM_COMMAND)
OPEN = ("active", "pending")  # statuses a row leaves later, in place
WATCHED = (*APPENDED, *CHANGING, keys.ACTIVE_STRATEGY, keys.MAP, keys.CHARGING_STATION)


class _Channel(Protocol):
    def log(self, message: Any, *, log_time: int | None = None) -> None: ...


@dataclass
class Counts:
    messages: int = 0
    per_topic: dict[str, int] = field(default_factory=dict)


class Recorder:
    """Records into ``path`` (which must not exist) until :meth:`close`."""

    def __init__(
        self, path: Path, source: RecordSource, clock: SimClock, *, period_s: float = 0.5
    ) -> None:
        self.path, self.source, self.clock, self.period_s = path, source, clock, period_s
        self.counts = Counts()
        self._channels: dict[str, _Channel] = {}
        self._last: dict[str, int] = {}  # table -> newest id recorded
        self._status: dict[tuple[str, int], str] = {}  # (table, id) -> status recorded
        self._notified: dict[str, set[int]] = {t: set() for t in CHANGING}
        self._strategy: dict[str, str] = {}
        self._map_loaded: Any = None
        self._dirty: set[str] = set(WATCHED)
        self._wake = asyncio.Event()
        self._closed = False
        self._open()

    def _open(self) -> None:
        self.context = foxglove.Context()
        self.writer = foxglove.open_mcap(self.path, context=self.context)

    # -- input -----------------------------------------------------------------------------
    def note(self, n: bus.Notification) -> None:
        if n.table not in WATCHED:
            return
        self._dirty.add(n.table)
        if n.table in self._notified and n.id is not None:
            self._notified[n.table].add(n.id)
        self._wake.set()

    async def run(self, stop: asyncio.Event) -> None:
        """Read and record until ``stop`` is set; then a last read (what was committed before
        the stop is in the file)."""
        while not stop.is_set():
            await self.catch_up()
            waiter = asyncio.ensure_future(self._wake.wait())
            stopper = asyncio.ensure_future(stop.wait())
            await asyncio.wait(
                {waiter, stopper}, timeout=self.period_s, return_when="FIRST_COMPLETED"
            )
            waiter.cancel()
            stopper.cancel()
            if not self._wake.is_set():
                self._dirty.update(WATCHED)  # the period's read: whatever a lost hint hid
            self._wake.clear()
            await asyncio.sleep(0.02)  # gather a burst of notifications into one read
        self._dirty.update(WATCHED)
        await self.catch_up()

    async def catch_up(self) -> None:
        dirty, self._dirty = self._dirty, set()
        try:
            for table in APPENDED:
                if table in dirty:
                    await self._appended(table)
            for table in CHANGING:
                if table in dirty:
                    await self._changing(table)
            if keys.ACTIVE_STRATEGY in dirty:
                await self._strategies()
            if keys.MAP in dirty or keys.CHARGING_STATION in dirty:
                await self._world()
        except (OSError, TimeoutError, asyncpg.PostgresError, asyncpg.InterfaceError) as exc:
            log.warning("recorder: cannot read the tables (%s); retrying", exc)
            self._dirty |= dirty

    # -- reading ---------------------------------------------------------------------------
    async def _appended(self, table: str) -> None:
        while True:
            rows = await self.source.newer(table, self._last.get(table, 0))
            for record in rows:
                row = as_dict(record)
                self._last[table] = row["id"]
                self._record(table, row)
            if len(rows) < BATCH:
                return

    def _record(self, table: str, row: dict[str, Any]) -> None:
        robot, stamp = str(row["robot_id"]), float(row["stamp"])
        if table == keys.ODOMETRY:
            self.emit("/tf", fc.FrameTransformsChannel, topics.odometry_tf(row), stamp)
            self.emit(f"/{robot}/pose", fc.PoseInFrameChannel, topics.odometry_pose(row), stamp)
        elif table == keys.LASER_SCAN:
            self.emit(f"/{robot}/scan", fc.LaserScanChannel, topics.scan(row), stamp)
        elif table == keys.PLANNED_PATH:
            self.emit(f"/{robot}/path", fc.PosesInFrameChannel, topics.path(row), stamp)
        elif table == keys.COMMAND2ROBOT:
            self.emit(f"/{robot}/decisions", fc.LogChannel, topics.decision_log(row), stamp)
        elif table == keys.COMMAND_RECOMMENDATION:
            message = topics.json_ready(row, topics.RECOMMENDATION_COLUMNS)
            self.emit_json(
                f"/{robot}/recommendations", topics.RECOMMENDATION_SCHEMA, message, stamp
            )
        elif table == keys.BATTERY:
            message = topics.json_ready(row, topics.BATTERY_COLUMNS)
            self.emit_json(f"/{robot}/battery", topics.BATTERY_SCHEMA, message, stamp)
        elif table == keys.COLLISION_EVENT:
            text = f"collision with {row['other']} at ({row['x']:.2f}, {row['y']:.2f})"
            self.event(robot, stamp, text, "collision", LogLevel.Warning)

    async def _changing(self, table: str) -> None:
        notified, self._notified[table] = self._notified[table], set()
        # and every row still open: a change may come with another row's notification (a new
        # goal supersedes the old one in the same transaction, notified once)
        notified |= {i for (t, i), status in self._status.items() if t == table and status in OPEN}
        for record in await self.source.changed(table, self._last.get(table, 0), sorted(notified)):
            row = as_dict(record)
            self._last[table] = max(self._last.get(table, 0), row["id"])
            before = self._status.get((table, row["id"]))
            if before == row["status"]:
                continue
            self._status[(table, row["id"])] = row["status"]
            if table == keys.GOAL and before is None:  # where it is, once, even if seen late
                self._goal(row, self._stamp(row["stamp"]))
            self._changed(table, row)

    def _goal(self, row: dict[str, Any], stamp: float) -> None:
        message = topics.goal_pose(row, stamp)
        self.emit(f"/{row['robot_id']}/goal", fc.PoseInFrameChannel, message, stamp)

    def _changed(self, table: str, row: dict[str, Any]) -> None:
        robot, status = str(row["robot_id"]), row["status"]
        if table == keys.GOAL:
            stamp = self._stamp(row["finished_stamp"] if status != "active" else row["stamp"])
            where = f"({row['x']:.2f}, {row['y']:.2f})"
            reason = f": {row['reason']}" if row["reason"] else ""
            level = LogLevel.Warning if status == "failed" else LogLevel.Info
            self.event(robot, stamp, f"goal {row['id']} {where} {status}{reason}", "goal", level)
        elif table == keys.USER_COMMAND:
            what = f"{row['command']} {row['argument'] or ''}".strip()
            reason = f" ({row['reason']})" if row["reason"] else ""
            self.event(robot, self._stamp(None), f"user: {what}: {status}{reason}", "user_command")
        else:
            reason = row["status_reason"] or row["reason"]
            text = f"system: {row['command']}: {status}" + (f" ({reason})" if reason else "")
            self.event(robot, self._stamp(row["stamp"]), text, "system_command")

    async def _strategies(self) -> None:
        for record in await self.source.strategies():
            robot, code = str(record["robot_id"]), str(record["strategy_code"])
            if self._strategy.get(robot) == code:
                continue
            self._strategy[robot] = code
            text = f"strategy {code} (set by {record['source']})"
            self.event(robot, self._stamp(record["stamp"]), text, "strategy")

    async def _new_map(self) -> Any:
        """The newest map row when it was loaded since the last one written, else None."""
        row = await self.source.newest_map()
        if row is None or row["loaded_at"] == self._map_loaded:
            return None
        self._map_loaded = row["loaded_at"]
        return row

    async def _world(self) -> None:
        row = await self._new_map()
        if row is None:
            return
        stamp = self._stamp(None)
        self.emit("/map", fc.GridChannel, topics.map_grid(as_dict(row), stamp), stamp)
        stations = [as_dict(r) for r in await self.source.stations()]
        if stations:
            scene = topics.stations(stations, stamp)
            self.emit("/charging_stations", fc.SceneUpdateChannel, scene, stamp)

    def _stamp(self, stamp: float | None) -> float:
        """A row's sim time, or now on the sim's clock for a row that has none."""
        return float(stamp) if stamp is not None else self.clock.now()

    # -- output ----------------------------------------------------------------------------
    def emit(self, topic: str, kind: Callable[..., Any], message: Any, stamp: float) -> None:
        channel = self._channels.get(topic)
        if channel is None:
            channel = self._channels[topic] = kind(topic, context=self.context)
        channel.log(message, log_time=topics.nanos(stamp))
        self.counts.messages += 1
        self.counts.per_topic[topic] = self.counts.per_topic.get(topic, 0) + 1

    def emit_json(self, topic: str, schema: dict[str, Any], message: Any, stamp: float) -> None:
        if topic not in self._channels:
            self._channels[topic] = foxglove.Channel(topic, schema=schema, context=self.context)
        self.emit(topic, foxglove.Channel, message, stamp)

    def event(
        self, robot: str, stamp: float, text: str, name: str, level: LogLevel = LogLevel.Info
    ) -> None:
        message = topics.event_log(stamp, text, name, level)
        self.emit(f"/{robot}/events", fc.LogChannel, message, stamp)

    def close(self) -> None:
        """Finish the file (summary, indexes); safe to call twice."""
        if not self._closed:
            self._closed = True
            self.writer.close()

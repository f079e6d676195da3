"""Sensor records -> contract rows, batched per table, each batch followed by notifications.

Latency first: one long-lived task per table waits for rows; the first row after a quiet
spell is inserted on the next loop turn, alone. Rows that arrive while an INSERT is in
flight wait for it and then go together in the next one, so the writer keeps up with any
rate by growing its batches rather than its queue. Every batch is ONE statement per table:
``INSERT ... SELECT FROM unnest($1::text[], $2::float8[], ...) RETURNING id, robot_id``,
column arrays in, every new id out, which ``executemany`` could not give us (the
notifications need the newest id per robot). asyncpg prepares each statement once per
connection and reuses it. A scan batch sends all ranges as one flat real[] and each row
takes its slice, since Postgres arrays cannot hold rows of arrays.

After the INSERT (autocommitted, so already visible) the writer publishes one notification
per robot in the batch carrying that robot's newest id, as the contract asks.

The writer has its own small pool whose sessions run with ``synchronous_commit = off``:
a commit returns, and its rows are visible to every reader, without waiting for the WAL to
reach the disk. That fsync was most of the sensor-to-row latency (1-4 ms of the ~2-5 ms
measured with it on). The price: if Postgres itself crashes, the last few hundred
milliseconds of sensor rows may be lost (never corrupted), which is harmless for data that
is stale a moment later anyway. Commands and the world use the service's normal pool.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import asyncpg

from common.bus import Notifier
from common.contract import keys
from common.db import create_pool
from common.errors import ConnectionFailure
from common.tasks import cancel_and_wait
from services.bridge.counters import Counters, RateLimitedLog
from services.bridge.messages import BatteryState, Collision, LaserScan, Odometry, SensorRecord

logger = logging.getLogger("pnav.bridge.writer")

_ODOMETRY_SQL = f"""
INSERT INTO {keys.ODOMETRY} (robot_id, stamp, seq, x, y, yaw, linear_mps, angular_rps)
SELECT * FROM unnest($1::text[], $2::float8[], $3::int8[], $4::float8[], $5::float8[],
                     $6::float8[], $7::float8[], $8::float8[])
RETURNING id, robot_id"""

_LASER_SCAN_SQL = f"""
INSERT INTO {keys.LASER_SCAN} (robot_id, stamp, seq, angle_min, angle_increment,
                               range_min, range_max, ranges)
SELECT u.robot_id, u.stamp, u.seq, u.angle_min, u.angle_increment, u.range_min, u.range_max,
       ($8::real[])[u.first:u.last]
FROM unnest($1::text[], $2::float8[], $3::int8[], $4::float8[], $5::float8[], $6::float8[],
            $7::float8[], $9::int4[], $10::int4[])
     AS u(robot_id, stamp, seq, angle_min, angle_increment, range_min, range_max, first, last)
RETURNING id, robot_id"""

_BATTERY_SQL = f"""
INSERT INTO {keys.BATTERY} (robot_id, stamp, energy_wh, capacity_wh, percentage, charging,
                            power_w)
SELECT * FROM unnest($1::text[], $2::float8[], $3::float8[], $4::float8[], $5::float8[],
                     $6::bool[], $7::float8[])
RETURNING id, robot_id"""

_COLLISION_SQL = f"""
INSERT INTO {keys.COLLISION_EVENT} (robot_id, stamp, other, x, y)
SELECT * FROM unnest($1::text[], $2::float8[], $3::text[], $4::float8[], $5::float8[])
RETURNING id, robot_id"""


def _odometry_args(rows: Sequence[Any]) -> list[Any]:
    r: Sequence[Odometry] = rows
    return [
        [o.robot_id for o in r],
        [o.stamp for o in r],
        [o.seq for o in r],
        [o.x for o in r],
        [o.y for o in r],
        [o.yaw for o in r],
        [o.linear for o in r],
        [o.angular for o in r],
    ]


def _laser_scan_args(rows: Sequence[Any]) -> list[Any]:
    r: Sequence[LaserScan] = rows
    flat: list[float] = []
    first: list[int] = []
    last: list[int] = []
    for s in r:
        first.append(len(flat) + 1)  # Postgres arrays are 1-based, slices inclusive
        flat.extend(s.ranges)
        last.append(len(flat))
    return [
        [s.robot_id for s in r],
        [s.stamp for s in r],
        [s.seq for s in r],
        [s.angle_min for s in r],
        [s.angle_increment for s in r],
        [s.range_min for s in r],
        [s.range_max for s in r],
        flat,
        first,
        last,
    ]


def _battery_args(rows: Sequence[Any]) -> list[Any]:
    r: Sequence[BatteryState] = rows
    return [
        [b.robot_id for b in r],
        [b.stamp for b in r],
        [b.energy_wh for b in r],
        [b.capacity_wh for b in r],
        [b.percentage for b in r],
        [b.charging for b in r],
        [b.power_w for b in r],
    ]


def _collision_args(rows: Sequence[Any]) -> list[Any]:
    r: Sequence[Collision] = rows
    return [
        [c.robot_id for c in r],
        [c.stamp for c in r],
        [c.other for c in r],
        [c.x for c in r],
        [c.y for c in r],
    ]


@dataclass
class _Table:
    name: str
    sql: str
    args: Callable[[Sequence[Any]], list[Any]]
    pending: list[SensorRecord] = field(default_factory=list)
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    task: asyncio.Task[None] | None = None
    writing: bool = False  # a batch is being written (its rows not all notified yet)


TABLE_OF_RECORD: dict[type, str] = {
    Odometry: keys.ODOMETRY,
    LaserScan: keys.LASER_SCAN,
    BatteryState: keys.BATTERY,
    Collision: keys.COLLISION_EVENT,
}

# The connection, not the data, failed: retrying row by row would only fail more slowly.
_CONNECTION_LOST = (
    OSError,
    TimeoutError,
    asyncpg.InterfaceError,
    asyncpg.PostgresConnectionError,
    asyncpg.exceptions.OperatorInterventionError,  # admin shutdown, crash, cannot connect now
    ConnectionFailure,
)


class SensorWriter:
    """Queues sensor records and writes them as described in the module docstring.

    :meth:`add` is called on the loop's thread; :meth:`start` and :meth:`close` bracket the
    writer tasks (``close`` drains what is queued).
    """

    def __init__(
        self,
        database_url: str,
        notifier: Notifier,
        counters: Counters,
        *,
        max_pending: int = 10_000,
    ) -> None:
        self.database_url = database_url
        self.notifier = notifier
        self.pool: asyncpg.Pool | None = None
        self.counters = counters
        self.max_pending = max_pending
        self._alerts = RateLimitedLog(logger)
        self._closing = False
        # called on the loop whenever a table's writing goes idle (lockstep's reporter)
        self.on_idle: Callable[[], None] | None = None
        self._tables = {
            t.name: t
            for t in (
                _Table(keys.ODOMETRY, _ODOMETRY_SQL, _odometry_args),
                _Table(keys.LASER_SCAN, _LASER_SCAN_SQL, _laser_scan_args),
                _Table(keys.BATTERY, _BATTERY_SQL, _battery_args),
                _Table(keys.COLLISION_EVENT, _COLLISION_SQL, _collision_args),
            )
        }

    async def start(self) -> None:
        try:
            # One connection per table (each has one INSERT in flight at most), all opened
            # now and never retired for idleness: a cold connection's first INSERT costs
            # ~10 ms (catalog caches, planning), which would land on a sensor message.
            size = len(self._tables)
            self.pool = await create_pool(
                self.database_url,
                min_size=size,
                max_size=size,
                max_inactive_connection_lifetime=0,
                server_settings={
                    "synchronous_commit": "off",
                    "application_name": "pnav-bridge-sensors",
                },
            )
            await self._warm_up(self.pool, size)
        except (OSError, asyncpg.PostgresError, asyncpg.InterfaceError) as exc:
            raise ConnectionFailure(f"cannot open the bridge's sensor pool: {exc}") from exc
        for table in self._tables.values():
            table.task = asyncio.create_task(self._run(table), name=f"write-{table.name}")

    async def _warm_up(self, pool: asyncpg.Pool, size: int) -> None:
        """Prepare every INSERT on every connection by running it on empty arrays."""
        connections = [await pool.acquire() for _ in range(size)]
        try:
            for conn in connections:
                for table in self._tables.values():
                    await conn.fetch(table.sql, *table.args([]))
        finally:
            for conn in connections:
                await pool.release(conn)

    def add(self, record: SensorRecord) -> None:
        table = self._tables[TABLE_OF_RECORD[type(record)]]
        if len(table.pending) >= self.max_pending:
            # Postgres is behind or away: the newest sensor data is worth the most.
            del table.pending[0]
            self.counters.dropped[table.name] += 1
            self._alerts.warning(("overflow", table.name), "sensor queue full", table=table.name)
        table.pending.append(record)
        table.wake.set()

    def pending(self) -> int:
        return sum(len(t.pending) for t in self._tables.values())

    def idle(self) -> bool:
        """Every record added so far is written and notified (or dropped)."""
        return not any(t.pending or t.writing for t in self._tables.values())

    async def close(self, timeout_s: float = 5.0) -> None:
        """Write what is queued (within ``timeout_s``), then stop the tasks."""
        self._closing = True
        tasks = [t.task for t in self._tables.values() if t.task is not None]
        for table in self._tables.values():
            table.wake.set()
        if tasks:
            _, late = await asyncio.wait(tasks, timeout=timeout_s)
            await cancel_and_wait(late)
        if self.pool is not None:
            pool, self.pool = self.pool, None
            try:
                await asyncio.wait_for(pool.close(), timeout_s)
            except TimeoutError:
                pool.terminate()

    async def _run(self, table: _Table) -> None:
        while True:
            await table.wake.wait()
            table.wake.clear()
            table.writing = True
            try:
                while table.pending:
                    batch, table.pending = table.pending, []
                    try:
                        await self._write(table, batch)
                    except Exception:  # a bug must not end this table's writing for good
                        logger.exception("sensor batch failed", extra={"table": table.name})
            finally:
                table.writing = False
            if self.on_idle is not None:
                self.on_idle()
            if self._closing:
                return

    async def _write(self, table: _Table, batch: list[SensorRecord]) -> None:
        try:
            rows = await self._insert(table, batch)
        except _CONNECTION_LOST as exc:
            # Postgres away or restarting: drop this batch (sensor data goes stale in
            # milliseconds anyway), back off a little, and carry on with newer data.
            self.counters.dropped[table.name] += len(batch)
            self._alerts.warning(
                ("db_error", table.name), "sensor write failed", table=table.name, error=repr(exc)
            )
            await asyncio.sleep(0.2)
            return
        except Exception as exc:
            # The data was refused (a constraint, a robot deleted meanwhile, a value the
            # driver cannot encode): retry row by row so one bad row costs only itself.
            if len(batch) > 1:
                for record in batch:
                    await self._write(table, [record])
                return
            self.counters.rejected_by_db[table.name] += 1
            self._alerts.warning(
                ("rejected", table.name), "row refused", table=table.name, error=repr(exc)
            )
            return
        newest: dict[str, int] = {}
        for row_id, robot_id in rows:
            if row_id > newest.get(robot_id, 0):
                newest[robot_id] = row_id
        self.counters.rows_written[table.name] += len(rows)
        notify = self.notifier.notify
        for robot_id, row_id in newest.items():
            try:
                notify(table.name, robot_id, row_id)
            except Exception as exc:  # Zenoh closing: the row is written, the hint is lost
                self._alerts.warning(("notify", table.name), "notify failed", error=repr(exc))
        self.counters.batches[table.name] += 1
        if len(batch) > self.counters.largest_batch[table.name]:
            self.counters.largest_batch[table.name] = len(batch)

    async def _insert(self, table: _Table, batch: list[SensorRecord]) -> list[tuple[int, str]]:
        if self.pool is None:
            raise ConnectionFailure("the sensor writer is not started")
        async with self.pool.acquire() as conn:
            records = await conn.fetch(table.sql, *table.args(batch))
        return [(r[0], r[1]) for r in records]

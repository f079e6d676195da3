"""Sensor records -> contract rows, batched per table, each batch followed by notifications.

Latency first: one long-lived task per table waits for rows; the first row after a quiet
spell is inserted on the next loop turn, alone. Rows that arrive while an INSERT is in
flight wait for it and then go together in the next one, so the writer keeps up with any
rate by growing its batches rather than its queue. Every batch is ONE statement per table
for every robot in it (:mod:`services.bridge.sensor_tables`), prepared once per connection.

After the INSERT (autocommitted, so already visible) the writer publishes one notification
per robot in the batch carrying that robot's newest id and that row's image
(CONTRACT.md, "Row images"; none with ``PNAV_NOTIFY_IMAGES=off``). RETURNING gives the ids
in the order unnest fed the rows, which pairs each id with its record; the writer checks
that pairing (same length, same robot at each position) and sends no image if it fails.

The writer has its own small pool whose sessions run with ``synchronous_commit = off``:
a commit returns, and its rows are visible to every reader, without waiting for the WAL to
reach the disk. That fsync was most of the sensor-to-row latency (1-4 ms of the ~2-5 ms
measured with it on). A crash of Postgres itself can then lose the last few hundred
milliseconds of committed rows; the writer keeps what it wrote in the last seconds and
writes it again, ids and all, once its connections come back (replay.py), so no committed
row stays lost. Collision events are the exception: the robot forgets an event once its
row is acknowledged (acks.py), so their batches commit with ``synchronous_commit`` on, in a
transaction of their own. Commands and the world use the service's normal pool.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from dataclasses import dataclass, field

import asyncpg

from common.bus import Notifier
from common.db import create_pool
from common.errors import ConnectionFailure
from common.tasks import cancel_and_wait
from services.bridge.counters import Counters, RateLimitedLog
from services.bridge.replay import Replay
from services.bridge.sensor_payloads import SensorRecord
from services.bridge.sensor_tables import SENSOR_TABLES, SensorTable, newest_per_robot

logger = logging.getLogger("pnav.bridge.writer")


@dataclass
class _Table:
    spec: SensorTable
    pending: list[SensorRecord] = field(default_factory=list)
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    task: asyncio.Task[None] | None = None
    writing: bool = False  # a batch is being written (its rows not all notified yet)

    @property
    def name(self) -> str:
        return self.spec.name


TABLE_OF_RECORD: dict[type, str] = {record: t.name for record, t in SENSOR_TABLES.items()}

# The connection, not the data, failed: retrying row by row would only fail more slowly.
_CONNECTION_LOST = (
    OSError,
    TimeoutError,
    asyncpg.InterfaceError,
    asyncpg.PostgresConnectionError,
    asyncpg.exceptions.OperatorInterventionError,  # admin shutdown, crash, cannot connect now
    asyncpg.InternalClientError,  # a connection the server ended while idle (common.outage)
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
        # called with each batch once its rows are committed (or were already there), and
        # with a row the database refused for its values: the collision acks (acks.py)
        self.on_committed: Callable[[list[SensorRecord]], None] | None = None
        self._tables = {spec.name: _Table(spec) for spec in SENSOR_TABLES.values()}
        self.replay = Replay(list(SENSOR_TABLES.values()))
        self._started = False  # connections made from now on are renewals (replay.py)

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
                on_connect=self._connected,
                server_settings={
                    "synchronous_commit": "off",
                    "application_name": "pnav-bridge-sensors",
                },
            )
            await self._warm_up(self.pool, size)
            async with self.pool.acquire() as conn:
                await self.replay.read_window(conn)
        except (OSError, asyncpg.PostgresError, asyncpg.InterfaceError) as exc:
            raise ConnectionFailure(f"cannot open the bridge's sensor pool: {exc}") from exc
        self._started = True
        for table in self._tables.values():
            table.task = asyncio.create_task(self._run(table), name=f"write-{table.name}")

    async def _connected(self, conn: asyncpg.Connection) -> None:
        if self._started:
            self.replay.connections_renewed()

    async def _warm_up(self, pool: asyncpg.Pool, size: int) -> None:
        """Prepare every INSERT on every connection by running it on empty arrays."""
        connections = [await pool.acquire() for _ in range(size)]
        try:
            for conn in connections:
                for table in self._tables.values():
                    await conn.fetch(table.spec.sql, *table.spec.args([]))
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
            # milliseconds anyway), back off a little, and carry on with newer data, once
            # what a crash may have taken is back.
            self.replay.connections_renewed()
            self.counters.dropped[table.name] += len(batch)
            self._alerts.warning(
                ("db_error", table.name), "sensor write failed", table=table.name, error=exc
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
                ("rejected", table.name), "row refused", table=table.name, error=exc
            )
            self._committed(batch)
            return
        self.counters.rows_written[table.name] += len(rows)
        self.replay.written(table.name, rows, batch)
        notify = self.notifier.notify
        for robot_id, row_id, image in newest_per_robot(
            table.spec, batch, rows, images=self.notifier.images
        ):
            try:
                notify(table.name, robot_id, row_id, image)
            except Exception as exc:  # Zenoh closing: the row is written, the hint is lost
                self._alerts.warning(("notify", table.name), "notify failed", error=exc)
        self.counters.batches[table.name] += 1
        if len(batch) > self.counters.largest_batch[table.name]:
            self.counters.largest_batch[table.name] = len(batch)
        self._committed(batch)

    def _committed(self, batch: list[SensorRecord]) -> None:
        if self.on_committed is None:
            return
        try:
            self.on_committed(batch)
        except Exception as exc:  # the rows are written; the robot resends, nothing doubles
            self._alerts.warning(("committed", "hook"), "after-commit hook failed", error=exc)

    async def _insert(self, table: _Table, batch: list[SensorRecord]) -> list[tuple[int, str]]:
        if self.pool is None:
            raise ConnectionFailure("the sensor writer is not started")
        async with self.pool.acquire() as conn:
            if self.replay.pending(table.name):
                self.counters.rows_restored[table.name] += await self.replay.restore(
                    conn, table.name
                )
            if table.spec.durable:
                async with conn.transaction():
                    await conn.execute("SET LOCAL synchronous_commit TO on")
                    records = await conn.fetch(table.spec.sql, *table.spec.args(batch))
            else:
                records = await conn.fetch(table.spec.sql, *table.spec.args(batch))
        return [(r[0], r[1]) for r in records]

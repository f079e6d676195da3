"""Sensor rows a Postgres crash lost, written again with the ids they were given.

The writer commits sensor rows with ``synchronous_commit = off`` (writer.py): the commit
returns before the WAL reaches the disk, and the WAL writer flushes it within three of its
``wal_writer_delay`` (200 ms by default). A crash of the server in that gap loses rows that
were committed, visible and notified, and that later rows (a recommendation's provenance,
say) may name by id. The bridge still holds them: it keeps every row it wrote in the last
:attr:`Replay.window_s` seconds of successful writes, with its id, and when its connections
come back new (a connection error, or a pool that reconnected by itself), it writes them
again before anything newer: ``INSERT ... (..., id) ... ON CONFLICT (id) DO NOTHING``,
synchronously committed, so rows that survived cost nothing and lost ones return as they
were. Then the table's id sequence is moved past them, since a crash can take the
sequence's own advance with it and hand their ids out again.

The window is counted in the writer's own successful writes, not the wall clock, so an
outage of any length keeps what was written just before it. It is at least four WAL writer
periods (read from the server at start) and two seconds. What the bridge cannot restore: rows
written before a crash of the bridge and Postgres together (the buffer dies with it).
"""

from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import asyncpg

from common.outage import is_connection_error
from services.bridge.sensor_payloads import SensorRecord
from services.bridge.sensor_tables import SensorTable

logger = logging.getLogger("pnav.bridge.replay")

DEFAULT_WINDOW_S = 2.0
WAL_WRITER_PERIODS = 4  # the WAL writer flushes within three periods; one more for margin

_WAL_WRITER_DELAY_MS = "SELECT setting::float8 FROM pg_settings WHERE name = 'wal_writer_delay'"


def _sequence_past_sql(table: str) -> str:
    # nextval first, so the sequence never moves backwards; setval needs UPDATE on the
    # sequence, which the contract grants a table's writer (common/contract/roles.py)
    return (
        f"SELECT setval(pg_get_serial_sequence('{table}', 'id'), "
        f"greatest(nextval(pg_get_serial_sequence('{table}', 'id')), "
        f"(SELECT coalesce(max(id), 0) FROM {table})))"
    )


@dataclass
class _Written:
    """The rows of one table written within the window, oldest batch first."""

    batches: deque[tuple[float, list[int], list[SensorRecord]]] = field(default_factory=deque)
    suspect: bool = False  # the connections were renewed since: restore before writing


class Replay:
    """The writer's memory of its recent rows, per table, and their restoration."""

    def __init__(
        self,
        tables: Sequence[SensorTable],
        window_s: float = DEFAULT_WINDOW_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.window_s = window_s
        self.clock = clock
        self._tables = {t.name: t for t in tables if t.replay_sql is not None}
        self._written = {name: _Written() for name in self._tables}

    async def read_window(self, conn: asyncpg.Connection) -> None:
        """Stretch the window to the server's WAL writer period, if that is longer."""
        delay_ms = await conn.fetchval(_WAL_WRITER_DELAY_MS)
        if delay_ms is not None:
            self.window_s = max(self.window_s, WAL_WRITER_PERIODS * float(delay_ms) / 1000.0)

    def written(
        self, table: str, rows: Sequence[tuple[int, str]], batch: list[SensorRecord]
    ) -> None:
        """Remember a committed batch: ``rows`` are RETURNING's (id, robot) in the order
        unnest fed ``batch``, which is checked as the notifications check it (same length,
        same robot at each position); a batch that does not pair is not remembered, so a
        restore never puts one robot's reading under another's id."""
        memory = self._written.get(table)
        paired = len(rows) == len(batch) and all(
            robot == record.robot_id for (_, robot), record in zip(rows, batch, strict=True)
        )
        if memory is None or not paired:
            return
        now = self.clock()
        memory.batches.append((now, [row_id for row_id, _ in rows], batch))
        while memory.batches and memory.batches[0][0] < now - self.window_s:
            memory.batches.popleft()

    def connections_renewed(self) -> None:
        """Postgres may have restarted: every table restores its rows before its next write."""
        for memory in self._written.values():
            memory.suspect = True

    def remembered(self, table: str) -> list[int]:
        """The ids of ``table``'s rows in the window, oldest first."""
        memory = self._written.get(table)
        return [] if memory is None else [i for _, ids, _ in memory.batches for i in ids]

    def pending(self, table: str) -> bool:
        memory = self._written.get(table)
        return memory is not None and memory.suspect

    async def restore(self, conn: asyncpg.Connection, table: str) -> int:
        """Write ``table``'s remembered rows again; return how many were missing.

        A connection error propagates (the table stays suspect); rows the database now
        refuses (their robot deleted meanwhile) are given up with a warning."""
        memory = self._written[table]
        spec = self._tables[table]
        records = [r for _, _, batch in memory.batches for r in batch]
        ids = self.remembered(table)
        restored = 0
        if records and spec.replay_sql is not None:
            try:
                async with conn.transaction():
                    await conn.execute("SET LOCAL synchronous_commit TO on")
                    back = await conn.fetch(spec.replay_sql, *spec.args(records), ids)
                    await conn.execute(_sequence_past_sql(table))
                restored = len(back)
            except Exception as exc:
                if is_connection_error(exc):
                    raise
                logger.warning(
                    "cannot restore recent sensor rows", extra={"table": table, "error": str(exc)}
                )
        memory.suspect = False
        if restored:
            logger.warning(
                "restored sensor rows the database lost",
                extra={"table": table, "rows": restored, "remembered": len(ids)},
            )
        return restored

"""The safety layer's word on a command2robot row: one UPDATE after the cmd_vel went out.

The layer's verdict (:mod:`.safety`) is written on the row it judged (``safety``,
``sent_linear_mps``, ``sent_angular_rps``; migration 4) only when the layer did something
(limited, stopped) or could not look (unchecked): NULL means "sent as decided, clamped to
the robot's limits". The cmd_vel never waits for it: notes are queued and one task writes
them, all waiting ones in one ``executemany``. No notification follows: the decision on the
row did not change, and only people and status tools read the note (a notification would
wake every command2robot reader, the bridge first, for nothing).
"""

from __future__ import annotations

import asyncio
import logging
from collections import deque

import asyncpg

from common.contract import keys
from common.tasks import cancel_and_wait
from services.bridge.counters import RateLimitedLog

logger = logging.getLogger("pnav.bridge.notes")

_UPDATE = f"""
UPDATE {keys.COMMAND2ROBOT}
   SET safety = $2, sent_linear_mps = $3, sent_angular_rps = $4
 WHERE id = $1"""
# notes waiting while Postgres is slow; beyond it the oldest go (they are a record, not a
# command: the robot already got its cmd_vel)
MAX_PENDING = 10_000

Note = tuple[int, str, float, float]  # (command id, safety, sent linear, sent angular)


class SafetyNotes:
    def __init__(self, pool: asyncpg.Pool) -> None:
        self.pool = pool
        self._pending: deque[Note] = deque(maxlen=MAX_PENDING)
        self._wake = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._busy = False  # a batch is being written
        self._drained = asyncio.Event()  # nothing queued, nothing being written
        self._drained.set()
        self._alerts = RateLimitedLog(logger)
        self.written = 0
        self.failed = 0

    def start(self) -> None:
        self._task = asyncio.create_task(self._writer(), name="safety-notes")

    def add(self, command_id: int, safety: str, linear: float, angular: float) -> None:
        self._pending.append((command_id, safety, linear, angular))
        self._drained.clear()
        self._wake.set()

    def idle(self) -> bool:
        return not (self._pending or self._busy)

    async def close(self, within_s: float = 5.0) -> None:
        """Write what is queued (within ``within_s``), then stop."""
        if self._task is None:
            return
        try:
            async with asyncio.timeout(within_s):
                await self._drained.wait()
        except TimeoutError:
            logger.warning("safety notes not written at shutdown: %d", len(self._pending))
        await cancel_and_wait([self._task])
        self._task = None

    async def _writer(self) -> None:
        while True:
            await self._wake.wait()
            self._wake.clear()
            batch = list(self._pending)
            self._pending.clear()
            if not batch:
                continue
            self._busy = True
            try:
                async with self.pool.acquire() as conn:
                    await conn.executemany(_UPDATE, batch)
            except Exception as exc:  # Postgres away: the note is lost, the robot is safe
                self.failed += len(batch)
                self._alerts.warning("update", "safety note not written", error=exc)
                await asyncio.sleep(0.2)
            else:
                self.written += len(batch)
            finally:
                self._busy = False
            if self._pending:
                self._wake.set()
            else:
                self._drained.set()

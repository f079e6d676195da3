"""A pooled connection kept between statements: the fast way through asyncpg's pool.

A checkout of asyncpg's pool (``pool.acquire()`` and its release: a task for the shielded
release, a timeout, the idle timer re-armed) costs about as much client CPU as the statement
it serves: on the embedded Postgres a pooled one-row read or INSERT takes 76-82 us of the
service's CPU, the same on a connection already in hand 44 us
(``python -m pnav.bench.statement_cost``).
A scenario service sends its statements one after another (its engine runs one rule at a
time), so :class:`Lane` keeps one connection checked out and runs them on it:

- a statement that finds the lane free runs on its connection, taken from the pool the
  first time (and again after it was given back);
- one that finds it busy (two statements at once: a rule and the stats writer, say) takes a
  connection from the pool as before, so nothing ever waits on the lane;
- any error during a statement (a lost connection, a query cancelled halfway, a constraint
  the statement broke) gives the connection back to the pool, whose release cleans it up or
  replaces it, and the next statement takes a fresh one; a connection that closed while
  the lane held it (a Postgres restart, a terminated backend: the pool takes such a one back
  by itself) is let go before use;
- :meth:`close` gives it back (before the pool closes, which waits for every connection).

Nothing else changes: autocommit, the codecs the pool's ``init`` set, the pool's reconnects
after a Postgres restart. A pool of one connection is never held (the lane would starve
whoever else uses it): every statement checks out as before.
"""

from __future__ import annotations

from typing import Any

import asyncpg


class Lane:
    """Runs single statements on one held connection of ``pool`` (see the module)."""

    def __init__(self, pool: asyncpg.Pool) -> None:
        self.pool = pool
        self.enabled = pool.get_max_size() > 1
        self._conn: Any = None  # a pool connection proxy, checked out while held
        self._busy = False
        self.checkouts = 0  # connections taken for the lane (tests, benchmarks)
        self.overflows = 0  # statements that found the lane busy and used the pool

    async def fetch(self, sql: str, *args: Any) -> list[asyncpg.Record]:
        result: list[asyncpg.Record] = await self._run("fetch", sql, args)
        return result

    async def fetchrow(self, sql: str, *args: Any) -> asyncpg.Record | None:
        result: asyncpg.Record | None = await self._run("fetchrow", sql, args)
        return result

    async def fetchval(self, sql: str, *args: Any) -> Any:
        return await self._run("fetchval", sql, args)

    async def execute(self, sql: str, *args: Any) -> str:
        result: str = await self._run("execute", sql, args)
        return result

    async def _run(self, method: str, sql: str, args: tuple[Any, ...]) -> Any:
        if self._busy or not self.enabled:
            if self.enabled:
                self.overflows += 1
            async with self.pool.acquire() as conn:
                return await getattr(conn, method)(sql, *args)
        self._busy = True
        try:
            conn = self._conn
            if conn is not None and not self.holding:
                await self._give_back()  # closed while held: the pool renews it
                conn = None
            if conn is None:
                conn = self._conn = await self.pool.acquire()
                self.checkouts += 1
            return await getattr(conn, method)(sql, *args)
        except BaseException:
            await self._give_back()
            raise
        finally:
            self._busy = False

    @property
    def holding(self) -> bool:
        """Whether the lane holds a connection that is still open."""
        conn = self._conn
        if conn is None:
            return False
        try:
            return not conn.is_closed()
        except asyncpg.InterfaceError:
            return False  # the pool took it back itself when it saw the connection close

    async def _give_back(self) -> None:
        conn, self._conn = self._conn, None
        if conn is not None:
            await self.pool.release(conn)

    async def close(self) -> None:
        """Give the held connection back to the pool (call before closing the pool)."""
        await self._give_back()

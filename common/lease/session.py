"""The one dedicated Postgres connection that holds a replica's locks.

Every query on it goes through :meth:`LockSession._call`, and *any* exception from one means
the connection can no longer be trusted: it is closed at once and
:class:`~common.errors.ConnectionFailure` raised, whatever the exception's type. Telling a
lost session from a harmless error by type does not work: asyncpg reports a session that
Postgres ended while the connection was idle as ``InternalClientError`` on the next query
(its protocol is left in an error state, the socket may stay open, no termination listener
runs; MagicStack/asyncpg#1069, #784), and other paths may raise other types tomorrow. The
queries are written so that nothing expected makes them fail.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable
from typing import Any

import asyncpg

from common.config import LeaseSettings
from common.errors import ConnectionFailure
from common.lease import sql
from common.lease.share import Snapshot
from common.outage import outage_for


class LockSession:
    """A lock connection, open and joined (it holds the membership lock)."""

    def __init__(
        self, conn: asyncpg.Connection, pid: int, service: str, instance: str, timeout_s: float
    ) -> None:
        self.conn = conn
        self.pid = pid  # pg_locks.pid, robot_lease.backend_pid
        self.service = service
        self.instance = instance
        self.timeout_s = timeout_s

    @classmethod
    async def open(
        cls,
        url: str,
        service: str,
        instance: str,
        settings: LeaseSettings,
        *,
        old_pid: int | None,
        on_closed: Callable[[asyncpg.Connection], None],
        wait_s: float = 0.0,
    ) -> tuple[LockSession, list[str]]:
        """Connect, end the session ``old_pid`` of ours that may linger and close its history
        rows (``connection lost``; returns their robots), join; all of it tried again for
        ``wait_s`` (Postgres starting up). Raises :class:`ConnectionFailure`, at once for a
        database without the lease migration."""
        deadline = time.monotonic() + wait_s
        while True:
            try:
                conn, pid, closed = await _join(url, service, instance, settings, old_pid)
                break
            except Exception as exc:
                if isinstance(exc, asyncpg.UndefinedFunctionError):
                    raise ConnectionFailure(
                        f"the database has no robot leases (contract migration 2): run "
                        f"`pnav migrate` ({exc})"
                    ) from exc
                if time.monotonic() >= deadline:
                    raise ConnectionFailure(
                        f"{service}: cannot open the lease connection: {exc!r}"
                    ) from exc
            await asyncio.sleep(0.2)
        conn.add_termination_listener(on_closed)
        return cls(conn, pid, service, instance, statement_timeout(settings)), closed

    @property
    def alive(self) -> bool:
        return not self.conn.is_closed()

    def terminate(self) -> None:
        if not self.conn.is_closed():
            self.conn.terminate()

    async def _call(self, query: Callable[..., Awaitable[Any]], *args: object) -> Any:
        try:
            return await query(*args, timeout=self.timeout_s)
        except Exception as exc:
            self.terminate()
            raise ConnectionFailure(f"the lease connection is unusable: {exc!r}") from exc

    async def snapshot(self) -> Snapshot:
        rows = await self._call(self.conn.fetch, sql.SNAPSHOT, self.service)
        robots: list[str] = []
        holders: dict[str, int | None] = {}
        members: set[int] = set()
        for robot, pid in rows:
            if robot is None:
                members.add(pid)
            else:
                robots.append(robot)
                holders[robot] = pid
        return Snapshot(tuple(robots), holders, frozenset(members), self.pid)

    async def acquire(self, robot: str, takeover_wait_s: float) -> tuple[int, float] | None:
        """Take ``robot``: ``(robot_lease id, seconds to wait before acting)``, or None when
        another session holds it (or its row is gone)."""
        lease_id = await self._call(
            self.conn.fetchval, sql.ACQUIRE, self.service, robot, self.instance
        )
        if lease_id is None:
            return None
        wait_s = await self._call(
            self.conn.fetchval, sql.TAKEOVER_WAIT, self.service, robot, takeover_wait_s
        )
        return int(lease_id), float(wait_s or 0.0)

    async def release(self, robot: str, reason: str) -> None:
        await self._call(self.conn.fetchval, sql.RELEASE, self.service, robot, reason)

    async def leave(self, reason: str) -> None:
        """Close our remaining history rows (a lock taken by a call whose answer never came
        back: closing frees it), leave the members, close the connection."""
        await self._call(self.conn.execute, sql.CLOSE_MINE, self.service, reason)
        await self._call(self.conn.fetchval, sql.LEAVE, self.service)
        await self._call(self.conn.close)


async def _join(
    url: str, service: str, instance: str, settings: LeaseSettings, old_pid: int | None
) -> tuple[asyncpg.Connection, int, list[str]]:
    """One try of :meth:`LockSession.open`: the connection, its backend pid and the robots
    of ``old_pid``'s rows it closed. Raises on any failure."""
    timeout = statement_timeout(settings)
    name = f"pnav-lease {service}/{instance}"[:63]
    conn: asyncpg.Connection = await asyncpg.connect(
        url, timeout=timeout, server_settings={"application_name": name}
    )
    # The server answers: an outage this process's pools are backing off from is over.
    # Left to their next probe (up to 2 s away), the robots this session is about to take
    # would start scenarios whose every query fails at once, each failure ending and
    # restarting them, until a pool's probe found the database back.
    outage_for(url).recovered()
    try:
        # Postgres ends the session (and so frees our robots) if we go silent
        ms = int(settings.timeout_s * 1000)
        await conn.execute(f"SET idle_session_timeout = {ms}", timeout=timeout)
        pid = int(await conn.fetchval("SELECT pg_backend_pid()", timeout=timeout))
        closed: list[str] = []
        if old_pid is not None:
            try:
                await conn.fetchval(sql.END_OLD_SESSION, old_pid, name, timeout=timeout)
            except asyncpg.InsufficientPrivilegeError:
                pass  # another role's backend: the idle timeout will end it
            rows = await conn.fetch(
                sql.CLOSE_OLD_ROWS,
                service,
                instance,
                old_pid,
                sql.CONNECTION_LOST,
                timeout=timeout,
            )
            closed = [row["robot_id"] for row in rows]
        if not await conn.fetchval(sql.JOIN, service, timeout=timeout):
            raise ConnectionFailure("the membership lock is held exclusively")
    except BaseException:
        conn.terminate()
        raise
    return conn, pid, closed


def statement_timeout(settings: LeaseSettings) -> float:
    """A statement slower than this means the connection is not usable for leases."""
    return max(1.0, settings.timeout_s / 2)

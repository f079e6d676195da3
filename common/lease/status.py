"""Reading ownership from outside a replica (``pnav status``, tests): Postgres' locks are
the truth, robot_lease the history."""

from __future__ import annotations

import asyncpg

from common.contract import keys

_OWNERSHIP = f"""
SELECT h.robot_id, h.pid, l.instance
  FROM {keys.LEASE_HOLDERS_FN}($1) h
  LEFT JOIN {keys.ROBOT_LEASE} l ON l.service = $1 AND l.robot_id = h.robot_id
                                AND l.released_at IS NULL AND l.backend_pid = h.pid
 WHERE h.robot_id IS NOT NULL
 ORDER BY h.robot_id
"""
_REPLICAS = f"SELECT count(*) FROM {keys.LEASE_HOLDERS_FN}($1) WHERE robot_id IS NULL"
_HISTORY = f"""
SELECT robot_id, instance, acquired_at, released_at FROM {keys.ROBOT_LEASE}
 WHERE service = $1 ORDER BY robot_id, acquired_at, id
"""


async def ownership(conn: asyncpg.Connection, service: str) -> dict[str, str | None]:
    """Robot -> the instance of ``service`` that owns it now (None: nobody), as Postgres'
    locks say. An owner whose history row is not committed yet shows as ``pid:<backend>``."""
    out: dict[str, str | None] = {}
    for robot, pid, instance in await conn.fetch(_OWNERSHIP, service):
        out[robot] = None if pid is None else (instance or f"pid:{pid}")
    return out


async def live_replicas(conn: asyncpg.Connection, service: str) -> int:
    """How many replicas of ``service`` hold their membership lock now."""
    return int(await conn.fetchval(_REPLICAS, service))


async def history_overlaps(conn: asyncpg.Connection, service: str) -> list[str]:
    """Every pair of robot_lease rows of ``service`` whose tenures of one robot overlap
    (an open row followed by another, or a release after the next acquisition)."""
    problems = []
    previous: asyncpg.Record | None = None
    for row in await conn.fetch(_HISTORY, service):
        if previous is not None and previous["robot_id"] == row["robot_id"]:
            end = previous["released_at"]
            if end is None or end > row["acquired_at"]:
                problems.append(
                    f"{row['robot_id']}: {previous['instance']} held it until {end}, "
                    f"{row['instance']} took it at {row['acquired_at']}"
                )
        previous = row
    return problems

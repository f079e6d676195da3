"""What /metrics reads from the contract tables: the SQL of services/dashboard/stack_metrics.py.

Every read is a plain SELECT a foreign client may make (CONTRACT.md): ``engine_stats``,
the open ``robot_lease`` rows whose holder still holds its advisory lock (``pg_locks``, as
the lease protocol defines ownership), the newest id of each table, and the provenance of
new ``command2robot`` rows (their recommendation, and the sensor row it was derived from).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import asyncpg

from common.contract import keys

# Tables whose rows have an increasing ``id``: their rows written are counted by its advance.
ID_TABLES: tuple[str, ...] = (
    keys.ODOMETRY,
    keys.LASER_SCAN,
    keys.BATTERY,
    keys.COLLISION_EVENT,
    keys.GOAL,
    keys.USER_COMMAND,
    keys.COMMAND_RECOMMENDATION,
    keys.COMMAND2ROBOT,
    keys.SYSTEM_COMMAND,
    keys.ROBOT_LEASE,
    keys.PLANNED_PATH,
)
# recommendation input -> the sensor table it names (pnav/bench/provenance_samples.py: the scan
# starts a controller's recommendation, the odometry a planner's)
ORIGINS: tuple[tuple[str, str], ...] = (
    ("laser_scan", keys.LASER_SCAN),
    ("odometry", keys.ODOMETRY),
)

_ENGINE_SQL = f"""
SELECT service, instance, rule_type, scenario, executed, activated, acted, errors,
       total_time_s, max_time_s,
       extract(epoch FROM clock_timestamp() - updated_at)::float8 AS age_s
  FROM {keys.ENGINE_STATS}
"""
_LEASES_SQL = f"""
SELECT l.service, l.robot_id, l.instance
  FROM {keys.ROBOT_LEASE} l
  JOIN pg_locks k
    ON k.locktype = 'advisory' AND k.granted AND k.mode = 'ExclusiveLock' AND k.objsubid = 2
   AND k.database = (SELECT oid FROM pg_database WHERE datname = current_database())
   AND k.pid = l.backend_pid
   AND k.classid::bigint = {keys.LEASE_KEY_FN}(l.service)
   AND k.objid::bigint = {keys.LEASE_KEY_FN}(l.robot_id)
 WHERE l.released_at IS NULL
"""
_ROBOTS_SQL = f"SELECT count(*) FROM {keys.ROBOT}"
_COMMANDS_SQL = f"""
SELECT c.id, c.robot_id, c.recommendation_id, r.source, r.inputs,
       extract(epoch FROM c.created_at)::float8 AS decided,
       extract(epoch FROM r.created_at)::float8 AS recommended
  FROM {keys.COMMAND2ROBOT} c
  JOIN {keys.COMMAND_RECOMMENDATION} r ON r.id = c.recommendation_id
 WHERE c.id > $1 ORDER BY c.id LIMIT 5000
"""
_SENSED_SQL = "SELECT id, extract(epoch FROM received_at)::float8 FROM {table} WHERE id = ANY($1)"


@dataclass(frozen=True)
class EngineRow:
    service: str
    instance: str
    rule_type: str
    scenario: str
    executed: int
    activated: int
    acted: int
    errors: int
    total_time_s: float
    max_time_s: float
    age_s: float  # since the row was last written


@dataclass(frozen=True)
class Lease:
    service: str
    robot: str
    instance: str


@dataclass(frozen=True)
class Decided:
    """A command2robot row with the recommendation it obeyed (times: Postgres wall, s)."""

    command_id: int
    robot: str
    recommendation_id: int
    source: str
    inputs: Mapping[str, Any]
    decided: float
    recommended: float


class MetricsSource(Protocol):
    async def engine_stats(self) -> list[EngineRow]: ...
    async def leases(self) -> list[Lease]: ...
    async def robot_count(self) -> int: ...
    async def newest_ids(self) -> dict[str, int]: ...
    async def decided_since(self, after_id: int) -> list[Decided]: ...
    async def sensed_at(self, table: str, ids: Iterable[int]) -> dict[int, float]: ...


class SqlMetricsSource:
    """:class:`MetricsSource` on an asyncpg pool."""

    def __init__(self, pool: asyncpg.Pool) -> None:
        self.pool = pool

    async def engine_stats(self) -> list[EngineRow]:
        rows = await self.pool.fetch(_ENGINE_SQL)
        return [EngineRow(**dict(r)) for r in rows]

    async def leases(self) -> list[Lease]:
        rows = await self.pool.fetch(_LEASES_SQL)
        return [Lease(r["service"], r["robot_id"], r["instance"]) for r in rows]

    async def robot_count(self) -> int:
        count: int = await self.pool.fetchval(_ROBOTS_SQL)
        return count

    async def newest_ids(self) -> dict[str, int]:
        sql = " UNION ALL ".join(
            f"SELECT '{table}', coalesce(max(id), 0) FROM {table}" for table in ID_TABLES
        )
        return {table: int(newest) for table, newest in await self.pool.fetch(sql)}

    async def decided_since(self, after_id: int) -> list[Decided]:
        rows = await self.pool.fetch(_COMMANDS_SQL, after_id)
        return [
            Decided(
                r["id"],
                r["robot_id"],
                r["recommendation_id"],
                r["source"],
                _as_map(r["inputs"]),
                r["decided"],
                r["recommended"],
            )
            for r in rows
        ]

    async def sensed_at(self, table: str, ids: Iterable[int]) -> dict[int, float]:
        wanted = sorted(set(ids))
        if not wanted or table not in dict(ORIGINS).values():
            return {}
        rows = await self.pool.fetch(_SENSED_SQL.format(table=table), wanted)
        return {int(row_id): float(at) for row_id, at in rows}


def _as_map(value: Any) -> Mapping[str, Any]:
    """A jsonb column: a dict from a pool with the JSON codec (common.db), text otherwise."""
    if isinstance(value, str):
        try:
            value = json.loads(value)
        except ValueError:
            return {}
    return value if isinstance(value, dict) else {}


def origin_of(inputs: Mapping[str, Any]) -> tuple[str, int] | None:
    """(sensor table, row id) of the input that started a recommendation, if it names one."""
    for name, table in ORIGINS:
        row_id = inputs.get(name)
        if isinstance(row_id, int) and not isinstance(row_id, bool):
            return table, row_id
    return None

"""Every SQL statement the controller runs (the lease protocol's are in leases.py).

Reads: ``robot`` (limits), ``active_strategy`` + ``strategy`` (which behaviours, which
params), the newest ``laser_scan`` and ``odometry`` per robot. Writes: ``command_recommendation``
rows of kind ``robot``, and ``engine_stats``. Nothing else: that is all CONTRACT.md asks a
controller to touch.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import asyncpg

from examples.sql_controller.policy import VALIDITY_S, Advice, Robot, Scan

# One round trip per tick for every robot: what it follows, and the ids and stamps of its
# newest scan and odometry. The scan's 360 ranges are fetched only when there is a new scan
# to decide on (most ticks have none: the lidar runs at 5 Hz, the loop at 20 Hz or more).
_SITUATION = """
SELECT r.robot_id, r.max_linear_mps, r.max_angular_rps, r.footprint_radius_m,
       s.code AS strategy, s.controller_scenarios, s.params::text AS params,
       scan.id AS scan_id, scan.stamp AS scan_stamp,
       odom.id AS odom_id, odom.stamp AS odom_stamp, odom.linear_mps
  FROM robot r
  JOIN active_strategy a ON a.robot_id = r.robot_id
  JOIN strategy s ON s.code = a.strategy_code
  LEFT JOIN LATERAL (SELECT id, stamp FROM laser_scan
                      WHERE robot_id = r.robot_id ORDER BY id DESC LIMIT 1) scan ON true
  LEFT JOIN LATERAL (SELECT id, stamp, linear_mps FROM odometry
                      WHERE robot_id = r.robot_id ORDER BY id DESC LIMIT 1) odom ON true
 WHERE $1::text[] IS NULL OR r.robot_id = ANY($1::text[])
"""
_SCAN = """
SELECT id, stamp, angle_min, angle_increment, range_min, ranges FROM laser_scan WHERE id = $1
"""
_RECOMMEND = """
INSERT INTO command_recommendation (robot_id, kind, source, priority, linear_mps, angular_rps,
                                    stamp, expires_stamp, inputs, reason)
VALUES ($1, 'robot', $2, $3, $4, $5, $6, $7, $8::jsonb, $9)
RETURNING id
"""
# The scans a robot's recommendations were last made on, per source: after a restart or a
# take-over from another replica, a scan already used is not recommended on a second time.
_LAST_USED = """
SELECT source, (inputs->>'laser_scan')::bigint AS scan_id FROM command_recommendation
 WHERE robot_id = $1 AND kind = 'robot' AND source = ANY($2::text[])
 ORDER BY id DESC LIMIT 50
"""
_STATS = """
INSERT INTO engine_stats AS s (service, instance, rule_type, scenario, executed, activated,
                               acted, errors, total_time_s, max_time_s, updated_at)
VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, now())
ON CONFLICT (service, instance, rule_type) DO UPDATE SET
    scenario = EXCLUDED.scenario, executed = EXCLUDED.executed, activated = EXCLUDED.activated,
    acted = EXCLUDED.acted, errors = EXCLUDED.errors, total_time_s = EXCLUDED.total_time_s,
    max_time_s = EXCLUDED.max_time_s, updated_at = now()
"""


@dataclass(frozen=True)
class Situation:
    """One robot at one tick, as the tables show it."""

    robot: Robot
    strategy: str
    scenarios: tuple[str, ...]
    params: Mapping[str, Any]
    scan_id: int | None
    scan_stamp: float | None
    odom_id: int | None
    odom_stamp: float | None
    speed_mps: float


async def situations(pool: asyncpg.Pool, robots: Sequence[str] | None) -> list[Situation]:
    """Every robot with an active strategy (only ``robots`` unless None)."""
    rows = await pool.fetch(_SITUATION, None if robots is None else list(robots))
    out = []
    for row in rows:
        params = json.loads(row["params"])
        out.append(
            Situation(
                robot=Robot(
                    row["robot_id"],
                    row["max_linear_mps"],
                    row["max_angular_rps"],
                    row["footprint_radius_m"],
                ),
                strategy=row["strategy"],
                scenarios=tuple(row["controller_scenarios"]),
                params=params if isinstance(params, dict) else {},
                scan_id=row["scan_id"],
                scan_stamp=row["scan_stamp"],
                odom_id=row["odom_id"],
                odom_stamp=row["odom_stamp"],
                speed_mps=row["linear_mps"] or 0.0,  # no odometry yet: standing still
            )
        )
    return out


async def scan(pool: asyncpg.Pool, scan_id: int) -> Scan | None:
    """The scan's beams, or None if the retention policy pruned it meanwhile."""
    row = await pool.fetchrow(_SCAN, scan_id)
    if row is None:
        return None
    return Scan(
        row["id"],
        row["stamp"],
        row["angle_min"],
        row["angle_increment"],
        row["range_min"],
        list(row["ranges"]),
    )


async def last_used_scans(
    pool: asyncpg.Pool, robot_id: str, sources: Sequence[str]
) -> dict[str, int]:
    """source -> the newest scan it recommended on for this robot (any process, any time)."""
    used: dict[str, int] = {}
    for row in await pool.fetch(_LAST_USED, robot_id, list(sources)):
        if row["scan_id"] is not None:
            used.setdefault(row["source"], row["scan_id"])
    return used


async def recommend(
    pool: asyncpg.Pool, now: Situation, scan: Scan, advice: Sequence[Advice]
) -> int:
    """Write one robot's recommendations for one scan in one transaction; return the newest
    id (the caller notifies after this returns, i.e. after COMMIT)."""
    inputs: dict[str, Any] = {"laser_scan": scan.id, "scan_stamp": scan.stamp}
    if now.odom_id is not None:  # every behaviour here read the speed, even if only to see 0
        inputs.update(odometry=now.odom_id, odometry_stamp=now.odom_stamp)
    newest = 0
    async with pool.acquire() as conn, conn.transaction():
        for a in advice:
            # stamp: the scan's, so the row lives VALIDITY_S after what it was derived from
            row_id: int = await conn.fetchval(
                _RECOMMEND,
                now.robot.robot_id,
                a.source,
                a.priority,
                a.linear,
                a.angular,
                scan.stamp,
                scan.stamp + VALIDITY_S,
                json.dumps(inputs),
                a.reason,
            )
            newest = max(newest, row_id)
    return newest


async def write_stats(pool: asyncpg.Pool, rows: Sequence[tuple[Any, ...]]) -> None:
    if rows:
        await pool.executemany(_STATS, rows)

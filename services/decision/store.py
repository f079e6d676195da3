"""The decision service's SQL: one read of every live recommendation, and its two writes.

Each write is a single statement (a data-modifying CTE): the decision row and the
``treated_by`` of the rows it considered commit together, in one round trip, which keeps
the decision's latency to one query in and one out.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any, Final

from common.contract import keys
from common.db import Database
from services.decision.arbitration import Issued, Recommendation, RobotDecision, SystemDecision

# Every robot, with each of its live recommendations (none: one row of NULLs). The table is
# append-only and grows all run long, so each robot must be served by the
# (robot_id, kind, expires_stamp) index: `OFFSET 0` keeps the planner from flattening the
# lateral subquery into one hash join over the whole table (a sequential scan, measured at
# 20 ms for 200k rows against 0.1 ms this way).
LIVE_SQL: Final = """
SELECT r.robot_id, c.id, c.kind, c.source, c.priority, c.linear_mps, c.angular_rps,
       c.system_command, c.reason, c.treated_by
FROM robot r
LEFT JOIN LATERAL (
    SELECT id, kind, source, priority, linear_mps, angular_rps, system_command, reason,
           treated_by
    FROM command_recommendation c
    WHERE c.robot_id = r.robot_id AND c.kind IN ('robot', 'system') AND c.expires_stamp > $1
    OFFSET 0
) c ON true
"""

LAST_ISSUED_SQL: Final = """
SELECT r.robot_id, c.id, c.stamp, c.linear_mps, c.angular_rps, c.recommendation_id, c.source
FROM robot r
CROSS JOIN LATERAL (
    SELECT id, stamp, linear_mps, angular_rps, recommendation_id, source
    FROM command2robot c WHERE c.robot_id = r.robot_id ORDER BY id DESC LIMIT 1
) c
"""

WRITE_COMMAND2ROBOT_SQL: Final = """
WITH decision AS (
    INSERT INTO command2robot (robot_id, stamp, linear_mps, angular_rps, recommendation_id,
                               source, considered_ids, reason)
    VALUES ($1, $2, $3, $4, $5, $6, $7::bigint[], $8)
    RETURNING id
), treated AS (
    UPDATE command_recommendation SET treated_by = decision.id
    FROM decision WHERE command_recommendation.id = ANY($7::bigint[])
)
SELECT id FROM decision
"""

WRITE_SYSTEM_COMMAND_SQL: Final = """
WITH decision AS (
    INSERT INTO system_command (robot_id, command, recommendation_id, considered_ids, reason,
                                status, stamp)
    VALUES ($1, $2, $3, $4::bigint[], $5, 'pending', $6)
    RETURNING id
), treated AS (
    UPDATE command_recommendation SET treated_by = decision.id
    FROM decision WHERE command_recommendation.id = ANY($4::bigint[])
)
SELECT id FROM decision
"""


async def live_recommendations(db: Any, now: float) -> dict[str, list[Recommendation]]:
    """Robot id -> its live recommendations (every robot present, maybe with none)."""
    out: dict[str, list[Recommendation]] = defaultdict(list)
    for row in await db.fetch(LIVE_SQL, now):
        robot_id = row["robot_id"]
        if row["id"] is None:
            out[robot_id] = []
            continue
        out[robot_id].append(
            Recommendation(
                id=row["id"],
                robot_id=robot_id,
                kind=row["kind"],
                source=row["source"],
                priority=row["priority"],
                linear_mps=row["linear_mps"],
                angular_rps=row["angular_rps"],
                system_command=row["system_command"],
                reason=row["reason"],
                treated_by=row["treated_by"],
            )
        )
    return dict(out)


async def last_issued(db: Any) -> dict[str, Issued]:
    """Robot id -> its newest command2robot row (robots that never had one are absent)."""
    return {
        row["robot_id"]: Issued(
            row["id"],
            row["stamp"],
            row["linear_mps"],
            row["angular_rps"],
            row["recommendation_id"],
            row["source"],
        )
        for row in await db.fetch(LAST_ISSUED_SQL)
    }


async def write_robot_command(db: Database, d: RobotDecision) -> int:
    """Insert the command2robot row, mark what it considered, then notify command2robot."""
    value = await db.write(
        keys.COMMAND2ROBOT,
        d.robot_id,
        WRITE_COMMAND2ROBOT_SQL,
        d.robot_id,
        d.stamp,
        d.linear_mps,
        d.angular_rps,
        d.recommendation_id,
        d.source,
        list(d.considered_ids),
        d.reason,
    )
    return int(value)


async def write_system_command(db: Database, d: SystemDecision) -> int:
    """Insert the pending system_command row, mark what it considered, then notify."""
    value = await db.write(
        keys.SYSTEM_COMMAND,
        d.robot_id,
        WRITE_SYSTEM_COMMAND_SQL,
        d.robot_id,
        d.command,
        d.recommendation_id,
        list(d.considered_ids),
        d.reason,
        d.stamp,
    )
    return int(value)

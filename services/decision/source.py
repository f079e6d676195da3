"""The decision service's reads and writes of the contract: its SQL and its source.

:class:`DecisionSource` is the typed Protocol of those reads and writes (one read of every
live recommendation, the newest command per robot, and the writes); :class:`PgDecisionSource`
is its Postgres implementation (pnav.monolith.memory_decision has the in-memory one). The service's
:class:`~services.decision.store.DecisionStore` holds one and keeps what it read and wrote.

Each write is a single statement (a data-modifying CTE): the decision rows and the
``treated_by`` of the rows they considered commit together, in one round trip; each row's
notification carries its image. The commands decided for several robots in one activation
are ONE statement (:data:`WRITE_COMMANDS2ROBOT_SQL`, one commit for all of them): at 10 or
50 robots the commit, not the INSERT, is what a command costs.
"""

from __future__ import annotations

import functools
import logging
from collections import defaultdict
from collections.abc import Awaitable, Sequence
from typing import Any, Final, Protocol

from common.contract import keys
from common.contract.recommendations import Recommendation
from common.db import Database, batch_or_each
from services.decision.arbitration import COMMAND2ROBOT, Issued, RobotDecision, SystemDecision

logger = logging.getLogger("pnav.decision")

# Every robot, with each of its live recommendations (none: one row of NULLs). The table is
# append-only and grows all run long, so each robot must be served by the
# (robot_id, kind, expires_stamp) index: `OFFSET 0` keeps the planner from flattening the
# lateral subquery into one hash join over the whole table (a sequential scan, measured at
# 20 ms for 200k rows against 0.1 ms this way).
LIVE_SQL: Final = """
SELECT r.robot_id, c.id, c.kind, c.source, c.priority, c.linear_mps, c.angular_rps,
       c.system_command, c.stamp, c.expires_stamp, c.inputs, c.reason, c.treated_by
FROM robot r
LEFT JOIN LATERAL (
    SELECT id, kind, source, priority, linear_mps, angular_rps, system_command, stamp,
           expires_stamp, inputs, reason, treated_by
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

WRITE_COMMAND2ROBOT_SQL: Final = f"""
WITH decision AS (
{COMMAND2ROBOT.values_sql()}
), treated AS (
    UPDATE command_recommendation SET treated_by = decision.id
    FROM decision WHERE command_recommendation.id = ANY({COMMAND2ROBOT.param("considered_ids")})
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
        out[robot_id].append(Recommendation.of_row(row))
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
    """Insert the command2robot row, mark what it considered, then notify command2robot
    with the row's image (the bridge sends it without reading the table)."""
    value = await db.write(
        keys.COMMAND2ROBOT,
        d.robot_id,
        WRITE_COMMAND2ROBOT_SQL,
        *COMMAND2ROBOT.values(d),
        image=d.image(),
    )
    return int(value)


# Several robots' commands in one statement: column arrays in (unnest), one row per robot;
# each row's considered ids are its slice of one flat bigint[] (Postgres arrays cannot hold
# rows of arrays of different lengths), and each considered recommendation is marked treated
# by the command that considered it. RETURNING pairs every new id with its robot.
WRITE_COMMANDS2ROBOT_SQL: Final = f"""
WITH decision AS (
{COMMAND2ROBOT.batch_sql(returning="id, robot_id, considered_ids")}
), treated AS (
    UPDATE command_recommendation SET treated_by = decision.id
    FROM decision WHERE command_recommendation.id = ANY(decision.considered_ids)
)
SELECT id, robot_id FROM decision
"""


def commands_args(ds: Sequence[RobotDecision]) -> list[Any]:
    """The column arrays of :data:`WRITE_COMMANDS2ROBOT_SQL` for ``ds``."""
    return COMMAND2ROBOT.args(ds)


async def write_robot_commands(db: Database, ds: Sequence[RobotDecision]) -> list[int | None]:
    """Insert one command2robot row per decision (one robot each) in one statement, mark
    what each considered, then notify each robot with its row's image. Ids in the order of
    ``ds``; None for a row the database refused (then written one by one; logged)."""
    if len(ds) == 1:
        return [await write_robot_command(db, ds[0])]
    args = commands_args(ds)
    images = [(d.robot_id, d.image()) for d in ds]

    def batch() -> Awaitable[Sequence[int]]:
        return db.write_rows(keys.COMMAND2ROBOT, WRITE_COMMANDS2ROBOT_SQL, *args, images=images)

    return await batch_or_each(
        ds, batch, functools.partial(write_robot_command, db), "command2robot", logger
    )


async def write_system_command(db: Database, d: SystemDecision) -> int:
    """Insert the pending system_command row, mark what it considered, then notify with
    the row's image."""
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
        image=d.image(),
    )
    return int(value)


class DecisionSource(Protocol):
    """The decision service's reads and writes of the contract, typed."""

    async def live_recommendations(self, now: float) -> dict[str, list[Recommendation]]:
        """Robot id -> its live robot and system recommendations (every robot present)."""
        ...

    async def last_issued(self) -> dict[str, Issued]:
        """Robot id -> its newest command2robot row (robots never commanded are absent)."""
        ...

    async def write_robot_command(self, d: RobotDecision) -> int:
        """Insert the command2robot row and mark ``treated_by``; then notify. Its id."""
        ...

    async def write_robot_commands(self, ds: Sequence[RobotDecision]) -> list[int | None]:
        """Insert one command2robot row per decision (robots distinct) and mark what each
        considered, in one commit; then notify each. Ids in order; None: refused."""
        ...

    async def write_system_command(self, d: SystemDecision) -> int:
        """Insert the pending system_command row and mark ``treated_by``; then notify."""
        ...


class PgDecisionSource:
    """:class:`DecisionSource` on Postgres (pool reads, ``Database.write`` for the writes)."""

    def __init__(self, db: Database) -> None:
        self.db = db

    async def live_recommendations(self, now: float) -> dict[str, list[Recommendation]]:
        return await live_recommendations(self.db, now)

    async def last_issued(self) -> dict[str, Issued]:
        return await last_issued(self.db)

    async def write_robot_command(self, d: RobotDecision) -> int:
        return await write_robot_command(self.db, d)

    async def write_robot_commands(self, ds: Sequence[RobotDecision]) -> list[int | None]:
        return await write_robot_commands(self.db, ds)

    async def write_system_command(self, d: SystemDecision) -> int:
        return await write_system_command(self.db, d)

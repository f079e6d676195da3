"""The strategy service's SQL: what its meta rule scans for and what its target rules write.

These queries are the strategy service's own (records.py holds only reads every service
shares). Each command table is described once by a :class:`CommandTable` so user and system
commands go through the same rule with their own columns.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from typing import Any, Final

import asyncpg

from common.contract import keys


@dataclass(frozen=True)
class CommandTable:
    """A table of commands the strategy service treats (user_command or system_command)."""

    table: str
    # active_strategy.source for a change made by this table's commands
    source: str
    # the column the strategy service writes its reason into
    reason_column: str
    # whether the table has an `argument` column (system_command has none)
    has_argument: bool

    @property
    def snapshot_sql(self) -> str:
        argument = "c.argument" if self.has_argument else "NULL::text"
        return f"""
SELECT c.id, c.robot_id, c.command, {argument} AS argument, c.status,
       EXISTS (SELECT 1 FROM robot r WHERE r.robot_id = c.robot_id) AS known_robot,
       a.strategy_code, a.resume_code,
       ARRAY(SELECT code FROM strategy ORDER BY code) AS strategies
FROM {self.table} c LEFT JOIN active_strategy a ON a.robot_id = c.robot_id
WHERE c.id = $1
"""

    @property
    def treat_sql(self) -> str:
        # `status = 'pending'` makes treating a command idempotent: a row someone else
        # already treated is left alone and the transaction rolls back.
        return f"""
UPDATE {self.table} SET status = $2, {self.reason_column} = $3, treated_at = now()
WHERE id = $1 AND status = 'pending'
RETURNING id
"""


USER: Final = CommandTable(keys.USER_COMMAND, "user", "reason", has_argument=True)
SYSTEM: Final = CommandTable(keys.SYSTEM_COMMAND, "system", "status_reason", has_argument=False)
COMMAND_TABLES: Final = {t.table: t for t in (USER, SYSTEM)}


@dataclass(frozen=True)
class Pending:
    """A pending command, or (table = robot) a robot with no active_strategy row."""

    table: str
    id: int | None
    robot_id: str
    created_at: datetime | None
    has_active: bool
    known_robot: bool


# One round trip per meta activation: pending commands of both tables, and robots that
# still need their default strategy.
SCAN_SQL: Final = f"""
SELECT '{keys.USER_COMMAND}' AS tbl, c.id, c.robot_id, c.created_at,
       a.robot_id IS NOT NULL AS has_active,
       EXISTS (SELECT 1 FROM robot r WHERE r.robot_id = c.robot_id) AS known_robot
FROM user_command c LEFT JOIN active_strategy a ON a.robot_id = c.robot_id
WHERE c.status = 'pending'
UNION ALL
SELECT '{keys.SYSTEM_COMMAND}', c.id, c.robot_id, c.created_at,
       a.robot_id IS NOT NULL,
       EXISTS (SELECT 1 FROM robot r WHERE r.robot_id = c.robot_id)
FROM system_command c LEFT JOIN active_strategy a ON a.robot_id = c.robot_id
WHERE c.status = 'pending'
UNION ALL
SELECT '{keys.ROBOT}', NULL, r.robot_id, NULL, false, true
FROM robot r
WHERE NOT EXISTS (SELECT 1 FROM active_strategy a WHERE a.robot_id = r.robot_id)
"""


async def scan(db: Any) -> list[Pending]:
    rows = await db.fetch(SCAN_SQL)
    return [
        Pending(
            r["tbl"], r["id"], r["robot_id"], r["created_at"], r["has_active"], r["known_robot"]
        )
        for r in rows
    ]


@dataclass(frozen=True)
class CommandSnapshot:
    """A command row and its robot's strategy state, read in one query."""

    id: int
    robot_id: str
    command: str
    argument: str | None
    status: str
    known_robot: bool
    strategy_code: str | None
    resume_code: str | None
    strategies: frozenset[str]


async def snapshot(db: Any, table: CommandTable, command_id: int) -> CommandSnapshot | None:
    row = await db.fetchrow(table.snapshot_sql, command_id)
    if row is None:
        return None
    fields = dict(row)
    fields["strategies"] = frozenset(fields["strategies"] or ())
    return CommandSnapshot(**fields)


# Upsert guarded by the state the decision was made on: if the row changed since the rule
# read it (another writer), nothing is updated, the transaction rolls back, and the command
# stays pending for the next activation to decide again on fresh data.
SET_ACTIVE_SQL: Final = """
INSERT INTO active_strategy AS a
    (robot_id, strategy_code, resume_code, source, command_id, stamp, updated_at)
VALUES ($1, $2, $3, $4, $5, $6, now())
ON CONFLICT (robot_id) DO UPDATE SET
    strategy_code = EXCLUDED.strategy_code, resume_code = EXCLUDED.resume_code,
    source = EXCLUDED.source, command_id = EXCLUDED.command_id, stamp = EXCLUDED.stamp,
    updated_at = now()
WHERE a.strategy_code = $7 AND a.resume_code IS NOT DISTINCT FROM $8
RETURNING robot_id
"""

SET_DEFAULT_SQL: Final = """
INSERT INTO active_strategy (robot_id, strategy_code, source, stamp, updated_at)
SELECT r.robot_id, s.code, 'default', $3, now()
FROM robot r JOIN strategy s ON s.code = $2
WHERE r.robot_id = $1
ON CONFLICT (robot_id) DO NOTHING
RETURNING robot_id
"""


class StaleState(Exception):
    """Raised inside a transaction to roll it back: the rows changed since they were read."""


async def set_default(
    conn: asyncpg.Connection, robot_id: str, code: str, stamp: float | None
) -> bool:
    """Give ``robot_id`` strategy ``code`` if it has none; False if nothing was written."""
    return await conn.fetchval(SET_DEFAULT_SQL, robot_id, code, stamp) is not None

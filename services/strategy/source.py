"""The strategy service's raw reads and writes of the contract: its SQL,
:class:`StrategySource` (a Protocol) and :class:`PgStrategySource`, them in Postgres.
pnav.monolith.memory_strategy has them in memory; services/strategy/store.py keeps the sim clock and
the robots this replica owns, and gives the rules their view.

These queries are the strategy service's own (records.py holds only reads every service
shares). Each command table is described once by a :class:`CommandTable` so user and system
commands go through the same rule with their own columns.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, Protocol

from common.contract import keys
from common.contract.offers import LIVE_OFFERS_SQL, Offers
from common.db import Database
from services.strategy.commands import Outcome
from services.strategy.runnable import Needs
from services.strategy.view import CommandSnapshot, Pending, StaleState


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
       ARRAY(SELECT code FROM strategy ORDER BY code) AS strategies,
       (SELECT jsonb_object_agg(code, jsonb_build_array(planner_scenario,
                                                        controller_scenarios))
        FROM strategy) AS needs,
       (SELECT jsonb_agg(jsonb_build_array(o.service, o.scenario))
        FROM ({LIVE_OFFERS_SQL}) o) AS offers
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

STRATEGY_EXISTS_SQL: Final = "SELECT EXISTS (SELECT 1 FROM strategy WHERE code = $1)"


def command_table(name: str) -> CommandTable:
    """The :class:`CommandTable` called ``name``; a KeyError names a table never scanned."""
    return COMMAND_TABLES[name]


class StrategySource(Protocol):
    """The strategy service's reads and writes of the contract, typed."""

    async def scan(self) -> list[Pending]: ...

    async def snapshot(self, table: CommandTable, command_id: int) -> CommandSnapshot | None: ...

    async def treat(
        self, table: CommandTable, before: CommandSnapshot, outcome: Outcome, stamp: float | None
    ) -> None:
        """The command's status and reason and, if accepted, the robot's active_strategy
        (source ``table.source``), in one transaction guarded by ``before``; notify after
        commit. Raise :class:`StaleState` (writing nothing) if a row changed meanwhile."""
        ...

    async def strategy_exists(self, code: str) -> bool: ...

    async def set_default(self, robot_id: str, code: str, stamp: float | None) -> bool:
        """Give a known robot with no active_strategy row strategy ``code`` (source
        'default') if it exists; notify; False if nothing was written."""
        ...


class PgStrategySource:
    """:class:`StrategySource` on Postgres; writes notify after their commit."""

    def __init__(self, db: Database) -> None:
        self.db = db

    async def scan(self) -> list[Pending]:
        rows = await self.db.fetch(SCAN_SQL)
        return [
            Pending(
                r["tbl"], r["id"], r["robot_id"], r["created_at"], r["has_active"], r["known_robot"]
            )
            for r in rows
        ]

    async def snapshot(self, table: CommandTable, command_id: int) -> CommandSnapshot | None:
        row = await self.db.fetchrow(table.snapshot_sql, command_id)
        if row is None:
            return None
        fields = dict(row)
        fields["strategies"] = frozenset(fields["strategies"] or ())
        fields["needs"] = {
            code: Needs(planner, tuple(controller or ()))
            for code, (planner, controller) in (fields["needs"] or {}).items()
        }
        fields["offers"] = Offers.of((service, name) for service, name in fields["offers"] or ())
        return CommandSnapshot(**fields)

    async def treat(
        self, table: CommandTable, before: CommandSnapshot, outcome: Outcome, stamp: float | None
    ) -> None:
        status = "accepted" if outcome.accepted else "rejected"
        robot_id = before.robot_id
        async with self.db.transaction() as tx:
            treated = await tx.conn.fetchval(table.treat_sql, before.id, status, outcome.reason)
            if treated is None:
                raise StaleState("treated by someone else meanwhile")
            tx.changed(table.table, robot_id, before.id)
            if not outcome.accepted:
                return
            written = await tx.conn.fetchval(
                SET_ACTIVE_SQL,
                robot_id,
                outcome.strategy_code,
                outcome.resume_code,
                table.source,
                before.id,
                stamp,
                before.strategy_code,
                before.resume_code,
            )
            if written is None:
                raise StaleState("active_strategy changed since it was read")
            tx.changed(keys.ACTIVE_STRATEGY, robot_id)

    async def strategy_exists(self, code: str) -> bool:
        return bool(await self.db.fetchval(STRATEGY_EXISTS_SQL, code))

    async def set_default(self, robot_id: str, code: str, stamp: float | None) -> bool:
        async with self.db.transaction() as tx:
            written = await tx.conn.fetchval(SET_DEFAULT_SQL, robot_id, code, stamp) is not None
            if written:
                tx.changed(keys.ACTIVE_STRATEGY, robot_id)
        return written

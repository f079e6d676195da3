"""The strategy service's source on the in-memory contract, and its engine.

:class:`MemoryStrategySource` is :class:`~services.strategy.store.StrategySource` over
:class:`~pnav.monolith.contract.MemoryContract`: what ``PgStrategySource``'s SQL does, on the
rows as dicts (with the contract's column names). :func:`strategy_engine` seeds the
service's own meta rule on a given engine behind the service's own
:class:`~services.strategy.store.StrategyStore`.

The monolith does not run the strategy service yet (stack.py writes the episode's strategy
once); this is for the tick-by-tick tests and for the day it does.
"""

from __future__ import annotations

from collections.abc import Callable
from datetime import UTC, datetime

from common.contract import keys
from common.engine import Engine
from pnav.monolith.contract import MemoryContract, Row, owns_every_robot
from services.strategy import meta
from services.strategy.commands import Outcome
from services.strategy.runnable import Needs
from services.strategy.store import COMMAND_TABLES, CommandTable, StrategyStore
from services.strategy.view import CommandSnapshot, Pending, StaleState

# Postgres fills created_at (DEFAULT now()); a row written here without one sorts first.
_LONG_AGO = datetime(1970, 1, 1, tzinfo=UTC)


class MemoryStrategySource:
    """The strategy's reads and writes on a :class:`MemoryContract`."""

    def __init__(self, contract: MemoryContract) -> None:
        self.contract = contract

    # -- reads -------------------------------------------------------------------------------
    def _known(self, robot_id: str) -> bool:
        return self.contract[keys.ROBOT].newest(robot_id) is not None

    def _active(self, robot_id: str) -> Row | None:
        return self.contract[keys.ACTIVE_STRATEGY].newest(robot_id)

    def _codes(self) -> frozenset[str]:
        return frozenset(r["code"] for r in self.contract[keys.STRATEGY].all_rows())

    async def scan(self) -> list[Pending]:
        """As SCAN_SQL: both tables' pending commands, then robots with no strategy."""
        out: list[Pending] = []
        for name in COMMAND_TABLES:
            for row in self.contract[name].all_rows():
                if row["status"] == "pending":
                    robot_id = row["robot_id"]
                    has_active = self._active(robot_id) is not None
                    created = row.get("created_at") or _LONG_AGO
                    out.append(
                        Pending(
                            name, row["id"], robot_id, created, has_active, self._known(robot_id)
                        )
                    )
        for robot in self.contract[keys.ROBOT].all_rows():
            if self._active(robot["robot_id"]) is None:
                out.append(Pending(keys.ROBOT, None, robot["robot_id"], None, False, True))
        return out

    async def snapshot(self, table: CommandTable, command_id: int) -> CommandSnapshot | None:
        row = self.contract[table.table].by_id.get(command_id)
        if row is None:
            return None
        robot_id = row["robot_id"]
        active = self._active(robot_id) or {}
        return CommandSnapshot(
            id=command_id,
            robot_id=robot_id,
            command=row["command"],
            argument=row.get("argument") if table.has_argument else None,
            status=row["status"],
            known_robot=self._known(robot_id),
            strategy_code=active.get("strategy_code"),
            resume_code=active.get("resume_code"),
            strategies=self._codes(),
            needs={
                r["code"]: Needs(
                    r.get("planner_scenario"), tuple(r.get("controller_scenarios") or ())
                )
                for r in self.contract[keys.STRATEGY].all_rows()
            },
            offers=self.contract.offers(),
        )

    async def strategy_exists(self, code: str) -> bool:
        return code in self._codes()

    # -- writes (checked first, then applied, then notified: as one transaction) --------------
    async def treat(
        self, table: CommandTable, before: CommandSnapshot, outcome: Outcome, stamp: float | None
    ) -> None:
        row = self.contract[table.table].by_id.get(before.id)
        if row is None or row["status"] != "pending":
            raise StaleState("treated by someone else meanwhile")
        robot_id = before.robot_id
        active = self._active(robot_id)
        if (
            outcome.accepted
            and active is not None
            and (active["strategy_code"], active["resume_code"])
            != (before.strategy_code, before.resume_code)
        ):
            raise StaleState("active_strategy changed since it was read")
        status = "accepted" if outcome.accepted else "rejected"
        row.update({"status": status, table.reason_column: outcome.reason})
        row["treated_at"] = datetime.now(UTC)
        if outcome.accepted:
            change = {
                "strategy_code": outcome.strategy_code,
                "resume_code": outcome.resume_code,
                "source": table.source,
                "command_id": before.id,
                "stamp": stamp,
            }
            self._upsert(robot_id, change)
        self.contract.changed(table.table, robot_id, before.id)
        if outcome.accepted:
            self.contract.changed(keys.ACTIVE_STRATEGY, robot_id, None)

    async def set_default(self, robot_id: str, code: str, stamp: float | None) -> bool:
        if not self._known(robot_id) or code not in self._codes() or self._active(robot_id):
            return False
        change = {"strategy_code": code, "resume_code": None, "source": "default"}
        self._upsert(robot_id, change | {"command_id": None, "stamp": stamp})
        self.contract.changed(keys.ACTIVE_STRATEGY, robot_id, None)
        return True

    def _upsert(self, robot_id: str, change: Row) -> None:
        """The robot's one active_strategy row (its primary key), updated in place."""
        change["updated_at"] = datetime.now(UTC)
        active = self._active(robot_id)
        if active is None:
            self.contract.insert(
                keys.ACTIVE_STRATEGY, {"robot_id": robot_id, **change}, notify=False
            )
        else:
            active.update(change)


def user_command(
    contract: MemoryContract, robot_id: str, command: str, argument: str | None = None
) -> int:
    """What ``pnav.cli.stack_commands`` writes for a person's command (the table's defaults
    filled)."""
    row: Row = {"robot_id": robot_id, "command": command, "argument": argument}
    row["status"] = "pending"
    row |= {"reason": None, "created_at": datetime.now(UTC), "treated_at": None}
    return contract.insert(keys.USER_COMMAND, row)


def strategy_engine(
    contract: MemoryContract,
    engine: Engine,
    now: Callable[[], float | None],
    owns: Callable[[str], bool] = owns_every_robot,
) -> StrategyStore:
    """Seed the strategy's meta rule on ``engine`` as the service does; its store.

    ``now`` is sim time (None: not heard yet, stamps stay NULL); ``owns`` stands for the
    replica's leases. Hand the store every change notification (``store.note``).
    """
    store = StrategyStore(MemoryStrategySource(contract), now, owns)
    meta.seed(engine, store)
    return store

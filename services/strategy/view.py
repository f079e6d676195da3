"""What the strategy rules see of the contract: a Protocol and the records it returns.

:class:`~services.strategy.store.StrategyStore` implements :class:`StrategyView` on Postgres
in the service and on the in-memory contract in the monolith (pnav.monolith.memory_strategy). The
rules import this module and the pure ``commands`` only: no pool, no service, no SQL. A
command table is named by its contract name (``user_command``, ``system_command``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime
from typing import Protocol

from common.contract.offers import Offers
from services.strategy.commands import Outcome
from services.strategy.runnable import Needs


@dataclass(frozen=True)
class Pending:
    """A pending command, or (table = robot) a robot with no active_strategy row."""

    table: str
    id: int | None
    robot_id: str
    created_at: datetime | None
    has_active: bool
    known_robot: bool


@dataclass(frozen=True)
class CommandSnapshot:
    """A command row and its robot's strategy state, read together."""

    id: int
    robot_id: str
    command: str
    argument: str | None
    status: str
    known_robot: bool
    strategy_code: str | None
    resume_code: str | None
    strategies: frozenset[str]
    # what each strategy names, and what the live planners and controllers offer
    needs: Mapping[str, Needs] = field(default_factory=dict)
    offers: Offers = field(default_factory=Offers)


class StaleState(Exception):
    """A write found the rows changed since they were read: nothing was written (the
    transaction rolled back) and the command stays pending for the next look."""


class StrategyView(Protocol):
    """The strategy rules' view of the contract."""

    def owns(self, robot_id: str) -> bool:
        """Whether this replica handles ``robot_id`` now (docs/REPLICAS.md)."""
        ...

    async def pending(self) -> list[Pending]:
        """Pending commands of both tables, and robots with no active_strategy row."""
        ...

    async def snapshot(self, table: str, command_id: int) -> CommandSnapshot | None:
        """The command row of ``table`` and its robot's state (None: no such row)."""
        ...

    async def treat(self, table: str, before: CommandSnapshot, outcome: Outcome) -> None:
        """Write ``outcome`` on the command row and, if accepted, the robot's new strategy,
        together; raise :class:`StaleState` (writing nothing) if either row changed since
        ``before`` was read. Stamped with sim time."""
        ...

    async def strategy_exists(self, code: str) -> bool: ...

    async def set_default(self, robot_id: str, code: str) -> bool:
        """Give ``robot_id`` strategy ``code`` if it has none; False if nothing was written."""
        ...

    def should_warn(self, robot_id: str) -> bool:
        """True the first time it is asked for ``robot_id``: say a problem once, not every F."""
        ...

"""The strategy service's one data path: its source and its store.

- :class:`~services.strategy.source.StrategySource`: the raw typed reads and writes (the meta
  rule's scan, a command's snapshot, treating a command, the default strategy), with their
  SQL (services/strategy/source.py; re-exported here with
  :class:`~services.strategy.source.PgStrategySource`, its Postgres implementation);
  pnav.monolith.memory_strategy has the in-memory one.
- :class:`StrategyStore`: the one object the service holds; it stamps writes with sim time,
  answers ``owns`` and implements :class:`~services.strategy.view.StrategyView`, all the
  rules see.
"""

from __future__ import annotations

from collections.abc import Callable

from common.bus import Notification
from services.strategy.commands import Outcome
from services.strategy.source import (
    COMMAND_TABLES,
    CommandTable,
    PgStrategySource,
    StrategySource,
    command_table,
)
from services.strategy.view import CommandSnapshot, Pending

__all__ = [
    "COMMAND_TABLES",
    "CommandTable",
    "PgStrategySource",
    "StrategySource",
    "StrategyStore",
    "command_table",
]


def _everyone(_robot_id: str) -> bool:
    return True


class StrategyStore:
    """The strategy service's store: a :class:`StrategySource`, the sim clock, ownership.

    All the service's state is in the contract tables (active_strategy, the commands'
    status), so a restarted process carries on; the store keeps only which robots were
    warned about already. ``sim_now`` is None until the sim clock is heard (stamps stay
    NULL); ``owns`` stands for the replica's leases (every robot by default).
    """

    def __init__(
        self,
        source: StrategySource,
        sim_now: Callable[[], float | None],
        owns: Callable[[str], bool] = _everyone,
    ) -> None:
        self.source = source
        self.sim_now = sim_now
        self._owns = owns
        self._warned: set[str] = set()

    # -- StrategyView ----------------------------------------------------------------------
    def owns(self, robot_id: str) -> bool:
        return self._owns(robot_id)

    async def pending(self) -> list[Pending]:
        return await self.source.scan()

    async def snapshot(self, table: str, command_id: int) -> CommandSnapshot | None:
        return await self.source.snapshot(command_table(table), command_id)

    async def treat(self, table: str, before: CommandSnapshot, outcome: Outcome) -> None:
        await self.source.treat(command_table(table), before, outcome, self.sim_now())

    async def strategy_exists(self, code: str) -> bool:
        return await self.source.strategy_exists(code)

    async def set_default(self, robot_id: str, code: str) -> bool:
        return await self.source.set_default(robot_id, code, self.sim_now())

    def should_warn(self, robot_id: str) -> bool:
        if robot_id in self._warned:
            return False
        self._warned.add(robot_id)
        return True

    # -- what the service forwards -----------------------------------------------------------
    def note(self, note: Notification) -> None:
        """A change notification. Nothing to keep: the meta rule's one scan per activation
        is the read, and rows written without a notification are found by period F."""

"""The meta-strategy rule: detect pending commands and robots with no strategy.

A continuous rule (it clones itself). Each activation it reads, in one query, the pending
user_command and system_command rows and the robots that have no active_strategy row, and
creates the target rules of :mod:`services.strategy.scenario` for the robots this replica owns
(docs/REPLICAS.md):

- one :class:`ApplyDefaultStrategy` per robot with no active_strategy row;
- one :class:`ApplyCommand` per pending command, per robot in the order the commands were
  written (each table's rows in id order, the two tables merged by creation time). Commands
  of a robot still waiting for its default are left for the next activation.

The target rules go to the next queue ahead of this rule's clone, so every target rule has
run by the time the meta rule looks again: nothing is ever scheduled twice.
"""

from __future__ import annotations

import heapq
from collections import defaultdict
from collections.abc import Callable, Iterable
from datetime import datetime

from common.contract import keys
from common.engine import Engine, Rule
from services.strategy.scenario import ApplyCommand, ApplyDefaultStrategy, Chain
from services.strategy.view import Pending, StrategyView


def _order(command: Pending) -> tuple[datetime, str, int]:
    assert command.created_at is not None and command.id is not None
    return (command.created_at, command.table, command.id)


def in_order(commands: Iterable[Pending]) -> list[Pending]:
    """One robot's commands: each table's rows by id, the two tables merged by created_at.

    Ids order rows within a table; across the two tables only the creation time can.
    """
    per_table: dict[str, list[Pending]] = defaultdict(list)
    for command in commands:
        per_table[command.table].append(command)
    runs = [sorted(rows, key=lambda p: p.id or 0) for rows in per_table.values()]
    return list(heapq.merge(*runs, key=_order))


def plan(store: StrategyView, pending: list[Pending]) -> list[Rule]:
    """The target rules for what the scan found, defaults first."""
    rules: list[Rule] = []
    commands: dict[str, list[Pending]] = defaultdict(list)
    for item in pending:
        if item.known_robot and not store.owns(item.robot_id):
            # Replicas: another one owns this robot (docs/REPLICAS.md). A command naming an
            # unknown robot has no owner: every replica may reject it, the first one wins
            # (the status update is conditional on 'pending').
            continue
        if item.table == keys.ROBOT:
            rules.append(ApplyDefaultStrategy(store, item.robot_id))
        elif item.has_active or not item.known_robot:
            commands[item.robot_id].append(item)
    for robot_id in sorted(commands):
        chain = Chain()
        for item in in_order(commands[robot_id]):
            assert item.id is not None
            rules.append(ApplyCommand(store, item.table, item.id, robot_id, chain))
    return rules


class MetaStrategy(Rule):
    """Watches the command tables, the robots and the strategies; schedules target rules."""

    scenario = "strategy"
    meta = True
    watches = (keys.USER_COMMAND, keys.SYSTEM_COMMAND, keys.ROBOT, keys.STRATEGY)

    def __init__(self, store: StrategyView, hurry: Callable[[], None]) -> None:
        self.store = store
        self.hurry = hurry
        self.pending: list[Pending] = []
        self.targets: list[Rule] = []

    async def data_acquisition(self) -> None:
        self.targets = []
        self.pending = await self.store.pending()

    def activation_guards(self) -> bool:
        return bool(self.pending)

    def actions(self) -> None:
        self.targets = plan(self.store, self.pending)
        if self.targets:
            # Run them in the very next activation instead of waiting for the period F.
            self.hurry()

    def rule_generation(self) -> Iterable[Rule]:
        return [*self.targets, self.clone()]


def seed(engine: Engine, store: StrategyView) -> None:
    """Add the strategy's meta rule to ``engine`` (the service and the monolith both).

    ``hurry`` is handed to the rule as a callable, as in the decision service: scheduling
    is the engine's business, not the store's.
    """
    engine.add_meta(lambda: MetaStrategy(store, engine.hurry))

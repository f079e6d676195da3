"""The meta-strategy rule: detect pending commands and robots with no strategy.

A continuous rule (it clones itself). Each activation it reads, in one query, the pending
user_command and system_command rows and the robots that have no active_strategy row, and
creates the target rules of :mod:`services.strategy.apply` for the robots this replica owns
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
from collections.abc import Iterable
from datetime import datetime
from typing import TYPE_CHECKING

import services.strategy.store as store
from common.contract import keys
from common.engine import Rule
from services.strategy.apply import ApplyCommand, ApplyDefaultStrategy, Chain

if TYPE_CHECKING:
    from services.strategy.service import StrategyService


def _order(command: store.Pending) -> tuple[datetime, str, int]:
    assert command.created_at is not None and command.id is not None
    return (command.created_at, command.table, command.id)


def in_order(commands: Iterable[store.Pending]) -> list[store.Pending]:
    """One robot's commands: each table's rows by id, the two tables merged by created_at.

    Ids order rows within a table; across the two tables only the creation time can.
    """
    per_table: dict[str, list[store.Pending]] = defaultdict(list)
    for command in commands:
        per_table[command.table].append(command)
    runs = [sorted(rows, key=lambda p: p.id or 0) for rows in per_table.values()]
    return list(heapq.merge(*runs, key=_order))


def plan(service: StrategyService, pending: list[store.Pending]) -> list[Rule]:
    """The target rules for what the scan found, defaults first."""
    rules: list[Rule] = []
    commands: dict[str, list[store.Pending]] = defaultdict(list)
    for item in pending:
        if item.known_robot and not service.owns(item.robot_id):
            # Replicas: another one owns this robot (docs/REPLICAS.md). A command naming an
            # unknown robot has no owner: every replica may reject it, the first one wins
            # (the status update is conditional on 'pending').
            continue
        if item.table == keys.ROBOT:
            rules.append(ApplyDefaultStrategy(service, item.robot_id))
        elif item.has_active or not item.known_robot:
            commands[item.robot_id].append(item)
    for robot_id in sorted(commands):
        chain = Chain()
        for item in in_order(commands[robot_id]):
            assert item.id is not None
            table = store.COMMAND_TABLES[item.table]
            rules.append(ApplyCommand(service, table, item.id, robot_id, chain))
    return rules


class MetaStrategy(Rule):
    """Watches the command tables, the robots and the strategies; schedules target rules."""

    scenario = "strategy"
    meta = True
    watches = (keys.USER_COMMAND, keys.SYSTEM_COMMAND, keys.ROBOT, keys.STRATEGY)

    def __init__(self, service: StrategyService) -> None:
        self.service = service
        self.pending: list[store.Pending] = []
        self.targets: list[Rule] = []

    async def data_acquisition(self) -> None:
        self.targets = []
        self.pending = await store.scan(self.service.runtime.database.pool)

    def activation_guards(self) -> bool:
        return bool(self.pending)

    def actions(self) -> None:
        self.targets = plan(self.service, self.pending)
        if self.targets:
            # Run them in the very next activation instead of waiting for the period F.
            self.service.engine.hurry()

    def rule_generation(self) -> Iterable[Rule]:
        return [*self.targets, self.clone()]

"""Target rules of the strategy scenario: apply one command, or give a robot its default.

Each rule does one task and ends; the meta rule (:mod:`services.strategy.meta`) creates them.
A command's status update and the active_strategy change it causes commit together
(:meth:`StrategyView.treat`), and the notifications go out only after the commit. The rules
see the contract only through :class:`~services.strategy.view.StrategyView`.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

from common import log
from common.engine import Rule
from services.strategy.commands import DEFAULT_STRATEGY, RobotState, decide
from services.strategy.runnable import refusal
from services.strategy.view import CommandSnapshot, StaleState, StrategyView

logger = logging.getLogger("pnav.strategy")


@dataclass
class Chain:
    """The commands of one robot scheduled together, applied strictly in order.

    ``broken`` is set pessimistically by each rule as it starts and cleared only when it ends
    normally, so a command that failed (an exception discards its rule) or was deferred
    blocks the later ones of the same robot: they wait for the next meta activation, which
    schedules the robot's pending commands again from the oldest.
    """

    broken: bool = False


class ApplyCommand(Rule):
    """Apply one pending user_command or system_command row to its robot's strategy."""

    robot_id: str  # always one robot's rule

    scenario = "strategy"

    def __init__(
        self,
        store: StrategyView,
        table: str,
        command_id: int,
        robot_id: str,
        chain: Chain,
    ) -> None:
        self.store = store
        self.table = table
        self.command_id = command_id
        self.robot_id = robot_id
        self.chain = chain
        self.blocked = False
        self.snap: CommandSnapshot | None = None
        self.done = False

    async def data_acquisition(self) -> None:
        self.blocked = self.chain.broken
        self.chain.broken = True  # cleared in rule_generation if this rule ends well
        self.done = False
        self.snap = None
        if not self.blocked:
            self.snap = await self.store.snapshot(self.table, self.command_id)

    def activation_guards(self) -> Iterator[bool]:
        # An earlier command of this robot was not applied: keep the id order, wait.
        yield not self.blocked
        # Deleted, or treated by someone else since the meta rule saw it: nothing to do.
        yield self.snap is not None and self.snap.status == "pending"

    def conditions(self) -> Iterator[bool]:
        snap = self.snap
        # A known robot whose default strategy is not written yet: wait for it, since the
        # commands are defined relative to the current strategy.
        yield snap is not None and (snap.strategy_code is not None or not snap.known_robot)

    async def actions(self) -> None:
        snap = self.snap
        assert snap is not None  # guaranteed by the guards
        state = RobotState(snap.known_robot, snap.strategy_code, snap.resume_code)
        outcome = decide(
            snap.command,
            snap.argument,
            state,
            snap.strategies,
            lambda code: refusal(code, snap.needs, snap.offers),
        )
        try:
            await self.store.treat(self.table, snap, outcome)
        except StaleState as exc:
            self._log("command deferred", snap, why=str(exc))
            return
        self.done = True
        self._log(
            "command accepted" if outcome.accepted else "command rejected",
            snap,
            argument=snap.argument,
            outcome="accepted" if outcome.accepted else "rejected",
            reason=outcome.reason,
        )

    def _log(self, message: str, snap: CommandSnapshot, **more: object) -> None:
        """Log what became of this rule's command, naming it the same way every time."""
        log.event(
            logger,
            logging.INFO,
            message,
            robot=self.robot_id,
            table=self.table,
            command_id=self.command_id,
            command=snap.command,
            **more,
        )

    def rule_generation(self) -> Iterable[Rule]:
        gone = not self.blocked and (self.snap is None or self.snap.status != "pending")
        self.chain.broken = not (self.done or gone)
        return ()


class ApplyDefaultStrategy(Rule):
    """Give a robot with no active_strategy row the default strategy (source 'default')."""

    robot_id: str  # always one robot's rule

    scenario = "strategy"

    def __init__(self, store: StrategyView, robot_id: str) -> None:
        self.store = store
        self.robot_id = robot_id
        self.default_exists = False

    async def data_acquisition(self) -> None:
        self.default_exists = await self.store.strategy_exists(DEFAULT_STRATEGY)
        if not self.default_exists and self.store.should_warn(self.robot_id):
            # Said here, not in the guard (guards have no side effects); once per robot.
            log.event(
                logger,
                logging.ERROR,
                "default strategy missing from the strategy table",
                robot=self.robot_id,
                strategy=DEFAULT_STRATEGY,
            )

    def activation_guards(self) -> bool:
        return self.default_exists

    async def actions(self) -> None:
        if await self.store.set_default(self.robot_id, DEFAULT_STRATEGY):
            log.event(
                logger,
                logging.INFO,
                "default strategy set",
                robot=self.robot_id,
                strategy=DEFAULT_STRATEGY,
                outcome="accepted",
                source="default",
            )

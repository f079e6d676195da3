"""Target rules of the strategy scenario: apply one command, or give a robot its default.

Each rule does one task and ends; the meta rule (:mod:`services.strategy.meta`) creates them.
A command's status update and the active_strategy change it causes commit in one
transaction, and the notifications go out only after the commit.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import services.strategy.store as store
from common import log
from common.contract import keys
from common.engine import Rule
from services.strategy.commands import DEFAULT_STRATEGY, Outcome, RobotState, decide

if TYPE_CHECKING:
    from services.strategy.service import StrategyService

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

    scenario = "strategy"

    def __init__(
        self,
        service: StrategyService,
        table: store.CommandTable,
        command_id: int,
        robot_id: str,
        chain: Chain,
    ) -> None:
        self.service = service
        self.table = table
        self.command_id = command_id
        self.robot_id = robot_id
        self.chain = chain
        self.blocked = False
        self.snap: store.CommandSnapshot | None = None
        self.done = False

    async def data_acquisition(self) -> None:
        self.blocked = self.chain.broken
        self.chain.broken = True  # cleared in rule_generation if this rule ends well
        self.done = False
        self.snap = None
        if not self.blocked:
            pool = self.service.runtime.database.pool
            self.snap = await store.snapshot(pool, self.table, self.command_id)

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
        outcome = decide(snap.command, snap.argument, state, snap.strategies)
        try:
            await self._write(snap, outcome)
        except store.StaleState as exc:
            log.event(
                logger,
                logging.INFO,
                "command deferred",
                robot=self.robot_id,
                table=self.table.table,
                command_id=self.command_id,
                command=snap.command,
                why=str(exc),
            )
            return
        self.done = True
        log.event(
            logger,
            logging.INFO,
            "command accepted" if outcome.accepted else "command rejected",
            robot=self.robot_id,
            table=self.table.table,
            command_id=self.command_id,
            command=snap.command,
            argument=snap.argument,
            outcome="accepted" if outcome.accepted else "rejected",
            reason=outcome.reason,
        )

    async def _write(self, snap: store.CommandSnapshot, outcome: Outcome) -> None:
        db = self.service.runtime.database
        status = "accepted" if outcome.accepted else "rejected"
        async with db.transaction() as tx:
            treated = await tx.conn.fetchval(
                self.table.treat_sql, self.command_id, status, outcome.reason
            )
            if treated is None:
                raise store.StaleState("treated by someone else meanwhile")
            tx.changed(self.table.table, self.robot_id, self.command_id)
            if outcome.accepted:
                written = await tx.conn.fetchval(
                    store.SET_ACTIVE_SQL,
                    self.robot_id,
                    outcome.strategy_code,
                    outcome.resume_code,
                    self.table.source,
                    self.command_id,
                    self.service.sim_stamp(),
                    snap.strategy_code,
                    snap.resume_code,
                )
                if written is None:
                    raise store.StaleState("active_strategy changed since it was read")
                tx.changed(keys.ACTIVE_STRATEGY, self.robot_id)

    def rule_generation(self) -> Iterable[Rule]:
        gone = not self.blocked and (self.snap is None or self.snap.status != "pending")
        self.chain.broken = not (self.done or gone)
        return ()


class ApplyDefaultStrategy(Rule):
    """Give a robot with no active_strategy row the default strategy (source 'default')."""

    scenario = "strategy"

    def __init__(self, service: StrategyService, robot_id: str) -> None:
        self.service = service
        self.robot_id = robot_id
        self.default_exists = False

    async def data_acquisition(self) -> None:
        pool = self.service.runtime.database.pool
        self.default_exists = bool(
            await pool.fetchval(
                "SELECT EXISTS (SELECT 1 FROM strategy WHERE code = $1)", DEFAULT_STRATEGY
            )
        )

    def activation_guards(self) -> bool:
        if not self.default_exists and self.robot_id not in self.service.warned:
            # Say it once per robot, not every activation.
            self.service.warned.add(self.robot_id)
            log.event(
                logger,
                logging.ERROR,
                "default strategy missing from the strategy table",
                robot=self.robot_id,
                strategy=DEFAULT_STRATEGY,
            )
        return self.default_exists

    async def actions(self) -> None:
        db = self.service.runtime.database
        async with db.transaction() as tx:
            written = await store.set_default(
                tx.conn, self.robot_id, DEFAULT_STRATEGY, self.service.sim_stamp()
            )
            if written:
                tx.changed(keys.ACTIVE_STRATEGY, self.robot_id)
        if written:
            log.event(
                logger,
                logging.INFO,
                "default strategy set",
                robot=self.robot_id,
                strategy=DEFAULT_STRATEGY,
                outcome="accepted",
                source="default",
            )

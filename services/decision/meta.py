"""The meta-decision rule: arbitrate every robot's live recommendations.

A continuous rule (it clones itself), woken by every command_recommendation notification
and, as a fallback, every period F (which also drives the 0.1 s re-issue). Each activation:

1. one query reads every live recommendation (``expires_stamp`` > sim now) of every robot;
2. per robot, :func:`decide_robot` and :func:`decide_system` say what is due;
3. a target rule is created per row to write (:class:`IssueRobotCommand`,
   :class:`IssueSystemCommand`), and the engine is woken so they run in the very next
   activation rather than F later.

The target rules sit ahead of this rule's clone in the queue, so the next look at the table
already sees what they wrote (``treated_by``, the last command issued): nothing is decided
twice.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from typing import TYPE_CHECKING

import services.decision.store as store
from common import log
from common.contract import keys
from common.engine import Rule
from services.decision.arbitration import Recommendation, decide_robot, decide_system
from services.decision.robot_command import IssueRobotCommand
from services.decision.system_command import IssueSystemCommand

if TYPE_CHECKING:
    from services.decision.service import DecisionService

logger = logging.getLogger("pnav.decision")


class MetaDecision(Rule):
    scenario = "decision"
    meta = True
    watches = (keys.COMMAND_RECOMMENDATION, keys.ROBOT)

    def __init__(self, service: DecisionService) -> None:
        self.service = service
        self.clock_started = False
        self.now = 0.0
        self.live: dict[str, list[Recommendation]] = {}
        self.targets: list[Rule] = []

    async def data_acquisition(self) -> None:
        self.targets = []
        self.live = {}
        clock = self.service.runtime.clock
        # Expiry is in sim time: with no clock yet, "live" means nothing. Wait for the sim.
        self.clock_started = clock.started
        if not self.clock_started:
            return
        self.now = clock.now()
        pool = self.service.runtime.database.pool
        if not self.service.bootstrapped:
            # First look after start: carry on from the table, so a restart neither repeats
            # a stop nor forgets that a robot is moving.
            self.service.issued = await store.last_issued(pool)
            self.service.bootstrapped = True
            self.service.regained.clear()
        elif self.service.regained:
            # Robots taken over from another replica: carry on from what it issued last.
            regained, self.service.regained = self.service.regained, set()
            last = await store.last_issued(pool)
            for robot_id in regained:
                if robot_id in last:
                    self.service.issued[robot_id] = last[robot_id]
                else:
                    self.service.issued.pop(robot_id, None)
        live = await store.live_recommendations(pool, self.now)
        # Replicas: decide only for the robots this one owns (docs/REPLICAS.md).
        owns = self.service.owns
        self.live = {robot_id: recs for robot_id, recs in live.items() if owns(robot_id)}

    def activation_guards(self) -> bool:
        if not self.clock_started and not self.service.waiting_logged:
            self.service.waiting_logged = True
            log.event(logger, logging.INFO, "waiting for the sim clock before deciding")
        return self.clock_started

    def actions(self) -> None:
        issued = self.service.issued
        for robot_id in sorted(self.live):
            recs = self.live[robot_id]
            robot_recs = [r for r in recs if r.kind == "robot"]
            system_recs = [r for r in recs if r.kind == "system"]
            command = decide_robot(robot_id, robot_recs, issued.get(robot_id), self.now)
            if command is not None:
                self.targets.append(IssueRobotCommand(self.service, command))
            system = decide_system(robot_id, system_recs, self.now)
            if system is not None:
                self.targets.append(IssueSystemCommand(self.service, system))
        # A robot removed from the robot table (or now another replica's) has nothing left
        # to stop here.
        for robot_id in [r for r in issued if r not in self.live]:
            del issued[robot_id]
        if self.targets:
            self.service.engine.hurry()

    def rule_generation(self) -> Iterable[Rule]:
        return [*self.targets, self.clone()]

"""The planner's answer to a strategy it cannot run: the robot's goal fails with the reason.

A strategy names its scenarios by name. When the robot's strategy names a planner scenario
this planner does not have (no entry point installed here), or controller scenarios no live
controller offers (scenario_offer: a controller restarted without a plug-in), nothing would
drive the robot and its goal would stay ``active`` with no word. The meta-planner then runs
this rule as the robot's "move" rule instead: it publishes an empty path once (a local
controller stops following the old one) and fails every active goal of the robot, as it
comes, with the reason (``strategy X names controller scenario 'dwa' that no running
controller offers; offered: avoid_left, safety_stop``). It ends when the strategy changes or
the scenario is offered again (the meta-planner's spec changes).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import ClassVar

from common.contract import records
from services.planner.published_path import empty_row
from services.planner.target import RuleKey, Spec, TargetRule
from services.planner.view import PlannerView
from services.planner.world_model import RobotState


class Unrunnable(TargetRule):
    scenario = "unrunnable"
    kind: ClassVar[str] = "move"

    def __init__(self, view: PlannerView, key: RuleKey, spec: Spec) -> None:
        super().__init__(view, key, spec)
        self.why = spec.why
        self.robot: RobotState | None = None
        self.goal: records.Goal | None = None
        self.path_cleared = False
        self.failed: set[int] = set()  # goals already given up (or found no longer active)

    async def data_acquisition(self) -> None:
        self.goal = None
        self.robot = self.claim()
        if self.robot is not None:
            self.goal = await self.view.active_goal(self.robot)

    def activation_guards(self) -> Iterator[bool]:
        yield self.robot is not None
        yield self.view.started()  # the stamps are sim time

    def conditions(self) -> bool:
        goal = self.goal
        return not self.path_cleared or (goal is not None and goal.id not in self.failed)

    async def actions(self) -> None:
        now = self.view.now()
        if not self.path_cleared:
            await self.view.publish_path(empty_row(self.robot_id, now, None))
            self.path_cleared = True
        goal = self.goal
        if goal is None or goal.id in self.failed:
            return
        self.failed.add(goal.id)
        # only while the robot's strategy is still the one it cannot run: a goal given just
        # after a switch this rule has not yet been ended for is the new strategy's
        await self.fail_goal(goal.id, self.why, now, self.spec.strategy)

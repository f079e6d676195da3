"""What the planner's target rules share: a behaviour per robot and kind.

The meta-planner wants, per robot, one "move" rule (the strategy's planner scenario) and one
"battery" rule; ``common.engine.Supervisor`` starts, ends and restarts them
(meta.py). Each is keyed ``(robot_id, kind)`` and its spec names the rule class and the
strategy that wants it: any change of either ends the rule and starts a new one in the same
activation, so a new strategy always starts from a blank rule.
"""

from __future__ import annotations

import logging
from typing import Any, ClassVar, NamedTuple

from common import log
from common.contract import records
from common.engine.behaviour import Behaviour
from services.planner.view import PlannerView
from services.planner.world_model import RobotState

logger = logging.getLogger("pnav.planner")

RuleKey = tuple[str, str]  # (robot_id, kind)


class Spec(NamedTuple):
    rule: type[TargetRule]
    strategy: str  # the strategy code that wants it
    why: str = ""  # why the strategy cannot run (unrunnable.py); "" for any other rule


class TargetRule(Behaviour[RuleKey, Spec]):
    """A planner target rule: it sees the store through ``view``; one object runs from its
    start to its end (the base's rule generation queues it again while it lives)."""

    robot_id: str  # always one robot's rule

    kind: ClassVar[str] = ""  # "move" or "battery": one of each per robot

    def __init__(self, view: PlannerView, key: RuleKey, spec: Spec) -> None:
        super().__init__(key, spec)
        self.view = view
        self.robot_id = key[0]

    def claim(self) -> RobotState | None:
        """The robot's state while this rule is still wanted (None once it has ended)."""
        return self.view.robot(self.robot_id) if self.live else None

    def terminate(self, why: str) -> None:
        log.event(
            logger, logging.INFO, "planner rule ended", robot=self.robot_id, kind=self.kind, why=why
        )

    async def fail_goal(
        self, goal_id: int, why: str, stamp: float, strategy: str | None = None
    ) -> bool:
        """Mark the goal failed with ``why`` and say so; False, saying nothing, if it was no
        longer active (superseded or cancelled meanwhile: not ours to close) or, with
        ``strategy``, the robot's strategy is no longer that one."""
        if not await self.view.mark_failed(goal_id, self.robot_id, why, stamp, strategy):
            return False
        said: dict[str, Any] = {"goal": goal_id}
        if strategy is not None:
            said["strategy"] = strategy
        log.event(logger, logging.WARNING, "goal failed", robot=self.robot_id, **said, why=why)
        return True

    async def recommend_move(
        self,
        odom: records.Odometry,
        linear: float,
        angular: float,
        reason: str,
        inputs: dict[str, Any],
        *,
        priority: int,
        ttl_s: float,
    ) -> None:
        """Recommend a velocity from this rule (its scenario the source), stamped with the
        odometry it was decided from and valid ``ttl_s`` sim seconds."""
        await self.view.recommend_velocity(
            self.robot_id,
            source=self.scenario,
            priority=priority,
            linear=linear,
            angular=angular,
            stamp=odom.stamp,
            ttl_s=ttl_s,
            reason=reason,
            inputs=inputs,
        )

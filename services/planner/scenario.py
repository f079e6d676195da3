"""What both planner scenarios do; they differ only in how they turn a heading error into a
velocity (``select``).

One rule per robot, created by the meta-planner and cloning itself while it is still the
robot's planner scenario (its slot token matches). Per activation:

1. acquisition: the newest odometry, and the target (the active goal, or the chosen
   charging station, per the strategy's ``target`` param);
2. guards: still the robot's scenario, fresh odometry (within ODOM_MAX_AGE_S of sim time),
   a target;
3. conditions: something new to say (a new odometry row or a new target);
4. actions: reached? mark the goal reached and recommend one zero velocity; else follow the
   cached route and recommend the scenario's velocity (priority 10, valid 0.5 s).
"""

from __future__ import annotations

import logging
import math
from abc import abstractmethod
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any, ClassVar

from common import log
from common.contract import records
from common.engine import Rule
from services.planner.state import PlannerState, RobotInfo, RobotState, Target
from services.planner.tracking import Progress, heading_error

logger = logging.getLogger("pnav.planner")

PRIORITY = 10
VALIDITY_S = 0.5
ODOM_MAX_AGE_S = 1.0
SLOW_RADIUS_M = 0.6  # closer than this to the target: slow down in proportion
MIN_SPEED_FRACTION = 0.25  # ...but never below this fraction of max_linear


@dataclass(frozen=True)
class Movement:
    linear: float
    angular: float
    turning: bool  # turning in place (turn_then_move) rather than driving


def clamp(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))


def cruise_speed(max_linear: float, remaining_m: float) -> float:
    """Full speed, slowing down over the last SLOW_RADIUS_M so the robot does not overshoot."""
    fraction = min(1.0, max(MIN_SPEED_FRACTION, remaining_m / SLOW_RADIUS_M))
    return max_linear * fraction


async def target_of(state: PlannerState, robot: RobotState, x: float, y: float) -> Target | None:
    """The robot's target under its strategy's ``target`` param (None: nothing to go to)."""
    strategy = robot.strategy
    kind = strategy.params.get("target") if strategy else None
    if kind == "goal":
        goal = await records.active_goal(state.db.pool, robot.info.robot_id)
        return Target.of_goal(goal) if goal else None
    if kind == "nearest_charger":
        station = state.choose_station(robot, x, y)
        return Target.of_station(station) if station else None
    return None


class MoveScenario(Rule):
    kind: ClassVar[str] = "move"

    def __init__(self, state: PlannerState, robot_id: str, token: int) -> None:
        self.state = state
        self.robot_id = robot_id
        self.token = token
        self.turning = False  # turn_then_move's hysteresis: turning in place last time
        self.last_said: tuple[Any, ...] | None = None
        self.held: set[tuple[Any, ...]] = set()  # targets reached and stopped at
        self.robot: RobotState | None = None
        self.odom: records.Odometry | None = None
        self.target: Target | None = None
        self.sim_now = 0.0

    @abstractmethod
    def select(self, error: float, remaining_m: float, info: RobotInfo) -> Movement:
        """The velocity for a heading error (rad, CCW positive) and the distance left."""

    async def data_acquisition(self) -> None:
        self.robot = self.state.claim(self.robot_id, self.kind, self.token)
        self.odom = self.target = None
        if self.robot is None:
            return
        self.sim_now = self.state.now()
        self.odom = await records.newest_odometry(self.state.db.pool, self.robot_id)
        if self.odom is not None:
            self.target = await target_of(self.state, self.robot, self.odom.x, self.odom.y)

    def activation_guards(self) -> Iterator[bool]:
        yield self.robot is not None
        yield self.odom is not None and self.state.clock_started()
        assert self.odom is not None
        yield self.sim_now - self.odom.stamp <= ODOM_MAX_AGE_S
        yield self.target is not None

    def conditions(self) -> Iterator[bool]:
        assert self.odom is not None and self.target is not None
        yield (self.odom.id, self.target.key) != self.last_said

    async def actions(self) -> None:
        odom, target, robot = self.odom, self.target, self.robot
        assert odom is not None and target is not None and robot is not None
        self.last_said = (odom.id, target.key)
        distance = math.hypot(target.x - odom.x, target.y - odom.y)
        if distance <= target.reach_m or (target.key in self.held and distance <= target.hold_m):
            await self._arrived(odom, target, distance)
            return
        self.held.discard(target.key)
        progress = self.state.route_for(robot, odom.x, odom.y, target)
        error = heading_error(odom.x, odom.y, odom.yaw, progress.lookahead)
        move = self.select(error, progress.remaining_m, robot.info)
        self.turning = move.turning
        await self._recommend(
            odom, target, move.linear, move.angular, self._reason(move, error, progress, target)
        )

    async def _arrived(self, odom: records.Odometry, target: Target, distance: float) -> None:
        if target.key in self.held:
            return  # already stopped here: say nothing, the decision service stops the robot
        self.held.add(target.key)
        if target.goal_id is not None:
            if not await self.state.mark_reached(target.goal_id, self.robot_id, self.sim_now):
                return  # superseded or cancelled meanwhile: not ours to close
            log.event(
                logger, logging.INFO, "goal reached", robot=self.robot_id, goal=target.goal_id
            )
            reason = f"{target.label} reached ({distance:.2f} m away): stop"
        else:
            reason = f"at {target.label} ({distance:.2f} m from its centre): stop and charge"
        await self._recommend(odom, target, 0.0, 0.0, reason)

    async def _recommend(
        self, odom: records.Odometry, target: Target, linear: float, angular: float, reason: str
    ) -> None:
        inputs = {"odometry": odom.id, "odom_stamp": odom.stamp, **target.inputs()}
        strategy = self.robot.strategy if self.robot else None
        if strategy is not None:
            inputs["strategy"] = strategy.code
        await records.recommend_velocity(
            self.state.db,
            self.robot_id,
            source=self.scenario,
            priority=PRIORITY,
            linear=linear,
            angular=angular,
            stamp=odom.stamp,
            ttl_s=VALIDITY_S,
            reason=reason,
            inputs=inputs,
        )

    def _reason(self, move: Movement, error: float, progress: Progress, target: Target) -> str:
        verb = "turning toward" if move.turning else "driving to"
        return (
            f"{verb} waypoint {progress.waypoint}/{progress.waypoints}, heading error "
            f"{error:.2f} rad, {progress.remaining_m:.2f} m to {target.label}"
        )

    def rule_generation(self) -> Iterable[Rule]:
        # Live on only while still the robot's planner scenario: a strategy change ends us.
        robot = self.state.robots.get(self.robot_id)
        slot = robot.slots.get(self.kind) if robot else None
        return [self.clone()] if slot is not None and slot.token == self.token else []

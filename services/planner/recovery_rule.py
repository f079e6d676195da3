"""The recovery rule: one per robot whose strategy asks for it (``"recovery": true`` in its
params, with the goal as target), running recovery.py's machine on the robot's odometry.

1. acquisition: at most every EVAL_PERIOD_S of sim time, the newest odometry and the active
   goal; the newest laser scan only while a manoeuvre is on or about to start; then the
   machine's step, once the guards are known to hold (so guards and conditions only look);
2. guards: still wanted, fresh odometry, an active goal;
3. conditions: the step has something to do;
4. actions: ``drive``: a velocity recommendation (source ``recovery``, priority 70: above
   the local controllers and avoidance, below the safety band, so safety_stop and the
   bridge's safety layer still win; valid VALIDITY_S, short, so that the local controller
   takes over soon after a manoeuvre); ``replan``: the robot's route is dropped, so the move
   rule plans it again (and publishes it) from where the robot is now; ``fail``: the goal is
   set ``failed`` with the machine's reason, and one stop is recommended.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator
from typing import Any, ClassVar

import numpy as np

import services.planner.arrival as arrival
import services.planner.waypoints as waypoints
from common import log
from common.collision import collides_with_points
from common.contract import records
from common.footprint import Footprint
from common.trail import Trail
from services.planner.recovery import (
    NOTHING,
    ROTATE,
    Action,
    Machine,
    Observation,
    RecoveryParams,
)
from services.planner.scenario import ODOM_MAX_AGE_S
from services.planner.target import RuleKey, Spec, TargetRule
from services.planner.view import PlannerView
from services.planner.world_model import RobotState

logger = logging.getLogger("pnav.planner")

PRIORITY = 70
VALIDITY_S = 0.25
STOP_VALIDITY_S = 0.5
EVAL_PERIOD_S = 0.1  # sim s between two steps: a recommendation each, well inside VALIDITY_S
REAR_MARGIN_M = 0.1  # beyond the footprint and the distance to back up
FREER_HORIZON_M = 1.0  # how far the freer side is judged
REAR_CONE_RAD = math.radians(30)  # beams this close to straight back see the rear
TURN_MARGIN_M = 0.02  # room a turning footprint keeps from the returns, m
RETRACE_M = 0.2  # backing along the trail: the pose this far back along it is steered for
RETRACE_BEND_M = 0.05  # ... or the curvature the trail took over this much of it
RETRACE_AHEAD_M = 0.035  # the trail must cover one step and this much more


def surroundings(
    scan: records.LaserScan, footprint: Footprint, back_up_m: float, rotate_rad: float = 0.0
) -> tuple[bool, bool]:
    """(nothing seen behind within the back-up's reach, the left is the side to turn to).

    The room is measured from the footprint's outline: backing up, from its back edge (the
    straight travel back before the outline meets a return, plus REAR_MARGIN_M); turning,
    by how far the footprint turns either way, up to ``rotate_rad``, before it meets a return
    (a polygon's corners sweep; a disc's outline does not move). The side that turns farther
    is the one; when both turn as far, the side whose beams see farther.

    A lidar with no beams behind (the Jackal's 270 degrees) cannot say the rear is clear:
    it is not, and recovery rotates instead of backing up blind (safety_stop would stop
    every blind reverse anyway)."""
    ranges = scan.ranges.astype(np.float64)
    angles = scan.angles()
    valid = np.isfinite(ranges) & (ranges >= scan.range_min - 1e-4)
    finite = np.where(valid, ranges, 0.0)  # inf x cos(90 deg) would be nan
    x, y = finite * np.cos(angles), finite * np.sin(angles)
    points = np.stack([x, y], axis=1)[valid]
    if footprint.is_disc:
        r = footprint.radius_m  # a band a little wider than the disc, as it always was
        behind = valid & (x < 0) & (np.abs(y) < r + 0.05) & (-x < r + back_up_m + REAR_MARGIN_M)
        rear_clear = not bool(behind.any())
    else:
        rear_clear = footprint.travel_m(points, forward=False) >= back_up_m + REAR_MARGIN_M
    capped = np.where(valid, np.minimum(ranges, FREER_HORIZON_M), FREER_HORIZON_M)
    left, right = angles > 0, angles < 0
    left_open = float(capped[left].mean()) if left.any() else 0.0
    right_open = float(capped[right].mean()) if right.any() else 0.0
    left_freer = left_open >= right_open
    if not footprint.is_disc and rotate_rad > 0:
        # the side that turns farther before a corner meets a return: a box wedged beside
        # a post may turn some way from it and not at all toward it, though neither turn is
        # free all the way round
        left_turn = _free_turn(footprint, points, rotate_rad)
        right_turn = _free_turn(footprint, points, -rotate_rad)
        if left_turn != right_turn:
            left_freer = left_turn > right_turn
    return sees_back(scan) and rear_clear, left_freer


def sees_back(scan: records.LaserScan) -> bool:
    """Whether the lidar has beams straight behind the robot (a 270-degree one has not)."""
    return bool((np.abs(scan.angles()) >= math.pi - REAR_CONE_RAD).any())


def retrace(
    trail: Trail, footprint: Footprint, odom: records.Odometry, back_up_mps: float
) -> float | None:
    """The curvature (rad/m) that backs the robot up along ``trail`` and keeps its outline
    within where the trail's outlines were for one step and RETRACE_AHEAD_M beyond (the
    latency and braking at back-up speed, with room); 0 straight back if only that does;
    None if none does: nothing behind is known to be clear."""
    pose = (odom.x, odom.y, odom.yaw)
    ahead = back_up_mps * EVAL_PERIOD_S + RETRACE_AHEAD_M
    # the arc toward the trail's pose RETRACE_M back (steady, step after step), the bend
    # the trail took just behind (a robot that turned as it crept in), or straight: the
    # first that keeps to it (judged again at every step)
    curves = (trail.retrace_turn(pose, RETRACE_M), trail.turn_behind(pose, RETRACE_BEND_M))
    for k in (*curves, 0.0):
        if k is not None and trail.covers(footprint, pose, -back_up_mps, -back_up_mps * k, ahead):
            return k
    return None


def _free_turn(footprint: Footprint, points: np.ndarray[Any, Any], turn: float) -> float:
    """How far (rad, up to ``|turn|``) the footprint turns in place toward ``turn``'s side
    before it meets one of ``points``."""
    near = points[np.hypot(points[:, 0], points[:, 1]) <= footprint.circumscribed_m + TURN_MARGIN_M]
    # headings close enough that the outline moves at most half the margin between two
    steps = max(1, math.ceil(abs(turn) * footprint.circumscribed_m / (TURN_MARGIN_M / 2)))
    for k in range(1, steps + 1):
        if collides_with_points(footprint, (0.0, 0.0, turn * k / steps), near, TURN_MARGIN_M):
            return abs(turn) * (k - 1) / steps
    return abs(turn)


class Recovery(TargetRule):
    scenario = "recovery"
    kind: ClassVar[str] = "recovery"

    def __init__(self, view: PlannerView, key: RuleKey, spec: Spec) -> None:
        super().__init__(view, key, spec)
        self.machine = Machine()
        self.trail = Trail()  # where the robot has been: the way back a blind rear may take
        self.robot: RobotState | None = None
        self.odom: records.Odometry | None = None
        self.goal: records.Goal | None = None
        self.sim_now = 0.0
        self.evaluated_at = -math.inf
        self.action: Action = NOTHING

    async def data_acquisition(self) -> None:
        self.action = NOTHING
        self.odom = self.goal = None
        self.robot = self.claim()
        if self.robot is None or self.robot.strategy is None:
            return
        view = self.view
        self.sim_now = view.now()
        if 0.0 <= self.sim_now - self.evaluated_at < EVAL_PERIOD_S:
            return
        self.evaluated_at = self.sim_now
        self.odom = await view.newest_odometry(self.robot_id)
        if self.odom is not None:
            self.trail.note(self.odom.stamp, self.odom.x, self.odom.y, self.odom.yaw)
        self.goal = await view.active_goal(self.robot)
        if not all(self.activation_guards()):
            return
        assert self.odom is not None and self.goal is not None
        params = RecoveryParams.read(self.robot.strategy.params)
        info = self.robot.info
        radius = info.footprint_radius_m
        o = self._observe(self.odom, self.goal, radius)
        if self.machine.wants_scan(o, params):
            scan = await view.newest_scan(self.robot_id)
            if scan is not None:
                clear, left = surroundings(
                    scan, info.footprint, params.back_up_m, params.rotate_rad
                )
                back: float | None = None
                # (not while rotating: only a back-up reads it)
                turning = self.machine.state == ROTATE
                if not sees_back(scan) and not info.footprint.is_disc and not turning:
                    # blind behind: back up only where the robot has just been
                    speed = min(params.back_up_mps, info.max_linear_mps)
                    back = retrace(self.trail, info.footprint, self.odom, speed)
                    clear = back is not None
                o = self._observe(self.odom, self.goal, radius, clear, left, back)
        params = RecoveryParams(
            **{**vars(params), "back_up_mps": min(params.back_up_mps, info.max_linear_mps)}
        )
        self.action = self.machine.step(o, params)

    @staticmethod
    def _observe(
        odom: records.Odometry,
        goal: records.Goal,
        footprint_m: float,
        rear_clear: bool = True,
        left_freer: bool = True,
        back_turn: float | None = None,
    ) -> Observation:
        leg = waypoints.route_target(goal)  # the route's next pose, as its rows say
        return Observation(
            *(odom.stamp, odom.x, odom.y, odom.yaw, ("goal", goal.id), leg.x, leg.y),
            footprint_m,
            rear_clear,
            left_freer,
            leg.seq,
            leg.reach_m + arrival.ALIGN_SLACK_M,
            back_turn,
        )

    def activation_guards(self) -> Iterator[bool]:
        yield self.robot is not None
        yield self.odom is not None and self.view.started()
        assert self.odom is not None
        yield self.sim_now - self.odom.stamp <= ODOM_MAX_AGE_S
        yield self.goal is not None

    def conditions(self) -> bool:
        return self.action.kind != "none"

    async def actions(self) -> None:
        action, odom, goal, robot = self.action, self.odom, self.goal, self.robot
        assert odom is not None and goal is not None and robot is not None
        if action.kind == "drive":
            await self._recommend(odom, goal, action.linear, action.angular, action.reason)
        elif action.kind == "replan":
            robot.route = None  # the move rule plans again from here, around what it sees now
            self._log("recovery re-plan", goal=goal.id, why=action.reason)
        elif action.kind == "fail":
            await self._fail(odom, goal, action.reason)

    async def _fail(self, odom: records.Odometry, goal: records.Goal, why: str) -> None:
        """Give the goal up with ``why`` (only if it is still active) and stop the robot."""
        if not await self.fail_goal(goal.id, why, self.sim_now):
            return  # superseded or cancelled meanwhile: not ours to close
        reason = f"goal {goal.id} failed: {why}: stop"
        await self._recommend(odom, goal, 0.0, 0.0, reason, STOP_VALIDITY_S)

    async def _recommend(
        self,
        odom: records.Odometry,
        goal: records.Goal,
        linear: float,
        angular: float,
        reason: str,
        ttl_s: float = VALIDITY_S,
    ) -> None:
        inputs: dict[str, Any] = {"odometry": odom.id, "odom_stamp": odom.stamp, "goal": goal.id}
        await self.recommend_move(
            odom, linear, angular, reason, inputs, priority=PRIORITY, ttl_s=ttl_s
        )

    def _log(self, message: str, **fields: Any) -> None:
        log.event(logger, logging.WARNING, message, robot=self.robot_id, **fields)

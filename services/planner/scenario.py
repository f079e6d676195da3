"""The rule every move scenario runs in: the scenarios differ only in how they turn a heading
error into a velocity (``select``, common/planner_core/scenario.py).

A scenario is a ``common.planner_core.scenario.MoveScenario`` subclass in any package,
registered under the ``pnav.planner.scenarios`` entry points (docs/PLANNER.md); it needs
nothing of this service's. :func:`move_rule` makes it into a :class:`MoveRule`: one rule per
robot, started by the meta-planner's supervisor: one object that runs while it is still
the robot's planner scenario (a ``common.engine.Behaviour``). The rule stays here, not in
common/, because everything it does is the planner's own: the target (routes.Target), the
route and its progress (tracking.py), the planned_path rows (published_path.py), the robot's state
(world_model.py) and the store's view (view.py). Per activation:

1. acquisition: the newest odometry (at most every EVAL_PERIOD_S of sim time, unless a
   goal notification came or a recommendation is due by the cadence), the target (the active
   goal, or the chosen charging station, per the strategy's ``target`` param), and every
   SCAN_PERIOD_S the newest laser scan, for the unmapped obstacles to plan around; then,
   if the guards will hold, what the conditions test (the route, the velocity), so that
   guards and conditions only look;
2. guards: still the robot's scenario, fresh odometry (within ODOM_MAX_AGE_S of sim time),
   a target;
3. conditions: something new to say: a new odometry row or a new target, and then either
   the target was reached, or the velocity for it is worth sending (see ``due``): a new
   target, a material change from the last recommendation, or RECOMMEND_PERIOD_S of sim time
   since it (the odometry comes at 30 Hz; most rows change nothing worth a write);
4. actions: reached? mark the goal reached and recommend one zero velocity; else recommend
   the scenario's velocity on the cached route (priority 10, valid 0.5 s).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator
from typing import Any, ClassVar, cast

import services.planner.arrival as arrival
import services.planner.waypoints as waypoints
from common import log
from common.contract import records
from common.planner_core.scenario import Movement, MoveScenario
from services.planner.cadence import RECOMMEND_PERIOD_S, Said, due
from services.planner.published_path import PathKey, PathRow, empty_key, empty_row, route_row
from services.planner.routes import Target
from services.planner.target import RuleKey, Spec, TargetRule
from services.planner.tracking import Progress, Route, heading_error
from services.planner.view import PlannerView
from services.planner.world_model import RobotState

logger = logging.getLogger("pnav.planner")

PRIORITY = 10
VALIDITY_S = 0.5
ODOM_MAX_AGE_S = 1.0
# How often (sim s) the newest laser scan is read, for unmapped obstacles (2 of its 5 Hz).
SCAN_PERIOD_S = 0.4
# The odometry wakes the planner 30 times a sim second; it is read (and the velocity worked
# out) at most this often, i.e. on every other row, unless a goal notification came or the
# cadence calls for a recommendation.
EVAL_PERIOD_S = 0.06
# A robot's odometry is looked at on its own notifications, or this long (the planner's
# clock: wall time in the service) after the last read in case one was lost.
ODOM_RECHECK_S = 0.25


async def target_of(
    view: PlannerView, robot: RobotState, x: float, y: float, done: dict[int, set[int]]
) -> tuple[Target | None, records.Goal | None]:
    """The robot's target under its strategy's ``target`` param (None: nothing to go to):
    the active goal's route's next pose (waypoints.py; ``done``: the waypoints this rule
    reached, per goal), or the nearest charger; and the goal."""
    strategy = robot.strategy
    kind = strategy.params.get("target") if strategy else None
    if kind == "goal":
        goal = await view.active_goal(robot)
        return (waypoints.route_target(goal, done.get(goal.id, ())), goal) if goal else (None, None)
    if kind == "nearest_charger":
        station = view.choose_station(robot, x, y)
        return (Target.of_station(station) if station else None), None
    return None, None


class MoveRule(TargetRule, MoveScenario):
    """A move scenario's rule: everything but ``select``, which the scenario supplies."""

    kind: ClassVar[str] = "move"

    def __init__(self, view: PlannerView, key: RuleKey, spec: Spec) -> None:
        super().__init__(view, key, spec)
        self.turning = False  # turn_then_move's hysteresis: turning in place last time
        self.last_said: tuple[Any, ...] | None = None  # (odometry id, target key) handled
        self.said: Said | None = None  # the last velocity recommended
        self.evaluated_at = -math.inf  # sim time the odometry was last read
        self.odometry_mark = -1  # the robot's odometry notifications already looked at
        self.odometry_read_at = -math.inf  # the store's clock at the last read
        self.held: set[tuple[Any, ...]] = set()  # targets reached and stopped at
        self.dropped: set[tuple[Any, ...]] = set()  # goals failed and stopped for
        self.robot: RobotState | None = None
        self.odom: records.Odometry | None = None
        self.target: Target | None = None
        self.goal: records.Goal | None = None
        self.done: dict[int, set[int]] = {}  # per goal: the waypoints this rule reached
        self.aligning: set[tuple[Any, ...]] = set()  # targets turned or settled at
        self.marks: list[tuple[Target, str, str | None]] = []  # waypoint progress to write
        self.ahead: waypoints.Ahead | None = None  # how far the route is judged on the map
        self.sim_now = 0.0
        # What this activation found (data acquisition) for the conditions to test and the
        # actions to write.
        self.news = False  # a new odometry row or a new target
        self.worth_saying = False  # reached and not stopped there yet, or the velocity is due
        self.arrived: float | None = None  # the distance to the target when it is reached
        self.failed: str | None = None  # why the map proves the goal unreachable
        self.move: Movement | None = None
        self.why = ""
        # The planned_path row (published_path.py): what was published last, and what is due now.
        self.published: PathKey | None = None
        self.path_due: tuple[PathKey, PathRow] | None = None

    async def data_acquisition(self) -> None:
        self.robot = self.claim()
        self.odom = self.target = self.goal = None
        self.news = False
        self.marks = []
        self.path_due = None
        if self.robot is None:
            return
        view = self.view
        self.sim_now = view.now()
        robot = self.robot
        said = self.said
        cadence_due = said is None or self.sim_now >= said.stamp + RECOMMEND_PERIOD_S - 0.005
        goal_news = view.goal_news(robot)
        # Every robot's odometry wakes the planner. This robot's rule looks only when a row
        # of its own was announced (or ODOM_RECHECK_S passed: notifications are hints), and
        # a row it skips is consumed: looking later, at another robot's wake-up, would act
        # on a row already tens of milliseconds old.
        notes, clock = view.odometry_notes(self.robot_id), view.clock()
        recheck = clock - self.odometry_read_at >= ODOM_RECHECK_S
        if notes == self.odometry_mark and not recheck and not goal_news:
            return
        self.odometry_mark = notes
        if (
            0.0 <= self.sim_now - self.evaluated_at < EVAL_PERIOD_S
            and not cadence_due
            and not goal_news
        ):
            return  # looked a moment ago, nothing is due, no new goal: skip this row
        self.odometry_read_at = clock
        self.evaluated_at = self.sim_now
        self.odom = await view.newest_odometry(self.robot_id)
        if self.odom is None:
            return
        robot.note_pose(self.odom)
        self.target, self.goal = await target_of(view, robot, self.odom.x, self.odom.y, self.done)
        if self.target is not None and abs(self.sim_now - robot.scan_read_at) >= SCAN_PERIOD_S:
            # The lidar, for the unmapped obstacles the route should go around (view.see).
            robot.scan_read_at = self.sim_now
            scan = await view.newest_scan(self.robot_id)
            if scan is not None and scan.id != (robot.seen.scan_id if robot.seen else None):
                view.see(robot, scan)
        if self.target is None:
            self._path_gone()
        if self._ready() and self.target is not None:
            self._evaluate()

    def _ready(self) -> bool:
        """The activation guards, as one test."""
        return all(self.activation_guards())

    def activation_guards(self) -> Iterator[bool]:
        yield self.robot is not None
        yield self.odom is not None and self.view.started()
        assert self.odom is not None
        yield self.sim_now - self.odom.stamp <= ODOM_MAX_AGE_S
        yield self.target is not None or self.path_due is not None

    def _evaluate(self) -> None:
        """What the conditions test: something new, then whether it is worth saying (and
        the velocity or the arrival to say)."""
        odom, target, robot = self.odom, self.target, self.robot
        assert odom is not None and target is not None and robot is not None
        self.news = (odom.id, target.key) != self.last_said
        if not self.news:
            return
        self.last_said = (odom.id, target.key)
        self.arrived, self.move, self.failed = None, None, None
        target = self.target = self._next_leg(odom, target, robot)
        bad = self._judge_ahead(robot)
        if bad is not None:  # a waypoint ahead the map rules out: the route fails now
            assert self.goal is not None  # only a goal's route is judged
            target = self.target = waypoints.waypoint_target(self.goal, bad[0])
            self.failed = waypoints.failure(target, bad[1])
            self.marks.append((target, "failed", self.failed))
            self.worth_saying = target.key not in self.dropped
            self._path_done(target)
            return
        distance = math.hypot(target.x - odom.x, target.y - odom.y)
        drives = robot.strategy is None or robot.strategy.params.get("planner_drives") is not False
        aligning = target.key in self.aligning
        there = arrival.at_position(target, distance, aligning)
        if target.poses and there:
            # there: turn to the heading and stand (whatever drives: a local controller has
            # stopped on the empty path), then the pose is reached
            move = arrival.final_move(
                target, odom.yaw, odom.angular_rps, odom.linear_mps, robot.info.max_angular_rps
            )
            if move is not None:
                self.aligning.add(target.key)
                self.move, self.why = move, arrival.why(target, move, odom.yaw)
                self.worth_saying = due(self.said, odom.stamp, target.key, move)
                self._path_done(target)
                return
        self.aligning.discard(target.key)
        if there or (target.key in self.held and distance <= target.hold_m):
            self.arrived = distance
            self.worth_saying = target.key not in self.held  # stopped there already: no
            self._path_done(target)
            return
        self.held.discard(target.key)
        progress = self.view.route_for(robot, odom.x, odom.y, target, odom.stamp)
        if progress.unreachable is not None and target.goal_id is not None:
            self.failed = waypoints.failure(target, progress.unreachable)
            if target.seq is not None:
                self.marks.append((target, "failed", self.failed))
            self.worth_saying = target.key not in self.dropped  # stopped for it already: no
            self._path_done(target)
            return
        if robot.route is not None and robot.route is not self.published:
            self.path_due = (robot.route, route_row(self.robot_id, odom.stamp, target, robot.route))
        error = heading_error(odom.x, odom.y, odom.yaw, progress.lookahead)
        remaining = progress.remaining_m + target.beyond_m  # slow only toward a halt
        move = self.select(error, remaining, robot.info, odom.angular_rps)
        self.move = move
        self.why = self._reason(move, error, progress, target)
        # A strategy whose local controller drives (``planner_drives`` false, e.g. GOTO_FAST)
        # gets the route, the arrival, the final turn and the failure from the planner, no
        # velocity on the way.
        self.worth_saying = drives and due(self.said, odom.stamp, target.key, move)

    def _judge_ahead(self, robot: RobotState) -> tuple[records.Waypoint, str] | None:
        """The next few waypoints of the goal's route judged on the map (waypoints.py)."""
        goal, data = self.goal, self.view.map_for(robot.info)
        if goal is None or not goal.waypoints or data is None:
            return None
        key = (goal.id, data.version, robot.info.footprint_radius_m)
        if self.ahead is None or self.ahead.key != key:
            self.ahead = waypoints.Ahead(key)
        return waypoints.check_ahead(data, robot.info.footprint_radius_m, goal, self.ahead)

    def _next_leg(self, odom: records.Odometry, target: Target, robot: RobotState) -> Target:
        """The target after the route's waypoints the robot is at now: each passed through
        within its tolerance, or halted at with its pose held and the robot standing, is
        reached (marked for the actions to write) and the next pose becomes the target."""
        goal = self.goal
        while target.seq is not None and goal is not None:
            distance = math.hypot(target.x - odom.x, target.y - odom.y)
            aligning = target.key in self.aligning
            if not arrival.at_position(target, distance, aligning):
                break
            if target.halts and arrival.final_move(
                target, odom.yaw, odom.angular_rps, odom.linear_mps, robot.info.max_angular_rps
            ):
                break  # turning or settling there still
            self.aligning.discard(target.key)
            self.done.setdefault(goal.id, set()).add(target.seq)
            self.marks.append((target, "reached", None))
            target = waypoints.route_target(goal, self.done[goal.id])
        return target

    def _path_done(self, target: Target) -> None:
        """The target is reached or failed: the path in force becomes an empty one."""
        key = empty_key(target)
        if self.published != key:
            self.path_due = (key, empty_row(self.robot_id, self.sim_now, target))

    def _path_gone(self) -> None:
        """No target any more (cancelled, or the strategy has none): an empty path, once,
        if a route was published."""
        if isinstance(self.published, Route):  # an empty one (reached, failed) says it already
            key = empty_key(None)
            self.path_due = (key, empty_row(self.robot_id, self.sim_now, None))

    def conditions(self) -> Iterator[bool]:
        yield bool(self.marks) or self.path_due is not None or (self.news and self.worth_saying)

    async def actions(self) -> None:
        for leg, status, why in self.marks:
            # a route's progress, on its rows (only while the goal is active)
            assert leg.goal_id is not None and leg.seq is not None
            await self.view.mark_waypoint(
                leg.goal_id, leg.seq, self.robot_id, status, why, self.sim_now
            )
            log.event(
                logger,
                logging.INFO,
                f"waypoint {status}",
                robot=self.robot_id,
                goal=leg.goal_id,
                waypoint=leg.seq,
            )
        if self.path_due is not None:
            # the path first: a local controller then stops on its empty path at once
            key, row = self.path_due
            await self.view.publish_path(row)
            self.published = key
        odom, target = self.odom, self.target
        assert odom is not None
        if target is None or not (self.news and self.worth_saying):
            return
        if self.arrived is not None:
            await self._arrived(odom, target, self.arrived)
            return
        if self.failed is not None:
            await self._failed(odom, target, self.failed)
            return
        move = self.move
        assert move is not None
        self.turning = move.turning
        self.said = Said(odom.stamp, target.key, move)
        await self._recommend(odom, target, move.linear, move.angular, self.why)

    async def _arrived(self, odom: records.Odometry, target: Target, distance: float) -> None:
        if target.key in self.held:
            return  # already stopped here: say nothing, the decision service stops the robot
        self.held.add(target.key)
        if target.goal_id is not None:
            if not await self.view.mark_reached(target.goal_id, self.robot_id, self.sim_now):
                return  # superseded or cancelled meanwhile: not ours to close
            log.event(
                logger, logging.INFO, "goal reached", robot=self.robot_id, goal=target.goal_id
            )
            reason = f"{target.label} reached ({distance:.2f} m away): stop"
            if target.yaw is not None:
                error = arrival.heading_error(target, odom.yaw)
                reason = (
                    f"{target.label} reached ({distance:.2f} m away, heading error "
                    f"{error:.2f} rad): stop"
                )
        else:
            reason = f"at {target.label} ({distance:.2f} m from its centre): stop and charge"
        self.said = Said(odom.stamp, target.key, Movement(0.0, 0.0, False))
        await self._recommend(odom, target, 0.0, 0.0, reason)

    async def _failed(self, odom: records.Odometry, target: Target, why: str) -> None:
        """The map proves the goal unreachable: mark it failed, recommend one stop."""
        self.dropped.add(target.key)
        assert target.goal_id is not None  # only goals fail
        if not await self.fail_goal(target.goal_id, why, self.sim_now):
            return  # superseded or cancelled meanwhile: not ours to close
        self.said = Said(odom.stamp, target.key, Movement(0.0, 0.0, False))
        await self._recommend(odom, target, 0.0, 0.0, f"{target.label} failed: {why}: stop")

    async def _recommend(
        self, odom: records.Odometry, target: Target, linear: float, angular: float, reason: str
    ) -> None:
        inputs = {"odometry": odom.id, "odom_stamp": odom.stamp, **target.inputs()}
        strategy = self.robot.strategy if self.robot else None
        if strategy is not None:
            inputs["strategy"] = strategy.code
        await self.recommend_move(
            odom, linear, angular, reason, inputs, priority=PRIORITY, ttl_s=VALIDITY_S
        )

    def _reason(self, move: Movement, error: float, progress: Progress, target: Target) -> str:
        verb = "turning toward" if move.turning else "driving to"
        return (
            f"{verb} waypoint {progress.waypoint}/{progress.waypoints}, heading error "
            f"{error:.2f} rad, {progress.remaining_m:.2f} m to {target.label}"
        )


_rules: dict[type[MoveScenario], type[MoveRule]] = {}


def move_rule(scenario: type[MoveScenario]) -> type[MoveRule]:
    """The rule class that runs ``scenario``: a subclass of both, named as the scenario (its
    name in logs and engine_stats), so that ``select`` sees the rule's state (``turning``)
    and may override a step as a subclass of the rule could. One class per scenario, so a
    strategy's spec is equal from one meta run to the next."""
    if issubclass(scenario, MoveRule):
        return scenario
    rule = _rules.get(scenario)
    if rule is None:
        made = type(
            scenario.__name__,
            (scenario, MoveRule),
            {"__module__": scenario.__module__, "__qualname__": scenario.__qualname__},
        )
        rule = _rules[scenario] = cast(type[MoveRule], made)
    return rule

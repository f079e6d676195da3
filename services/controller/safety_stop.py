"""safety_stop: never drive into something inside the footprint plus a margin.

The direction of travel comes from the newest odometry's measured velocity:

- moving forward (linear > 0.01 m/s): the obstacles the round body would sweep driving
  straight ahead (beams within ``footprint + safety_margin_m + |v| * safety_lookahead_s`` of
  the centre, in front of it, and within one footprint radius of its path);
- moving backward: the same behind the robot;
- not translating (stopped, or turning in place, which a round robot does without sweeping
  anything new): nothing, unless the robot is boxed in (an obstacle inside footprint + margin
  in each quadrant), when it recommends a full stop.

The look-ahead term counts the distance covered until the next scan (0.2 s at 5 Hz), and the
robot's braking distance at its acceleration limit (``v^2 / (2 max_linear_accel_mps2)``, the
robot row's), so the stop comes before the margin is used up rather than after.

Moving toward a side its lidar does not see (backing up with a 270-degree lidar), the robot
has no evidence the way is clear: it stops, and says so (``blind``), unless the robot is
retracing its own recent trail (a footprint polygon backing out of a pocket, recovery's
back-up): where its outline just was, for the distance the stop needs, nothing stood a
moment ago (common/trail.py, ``Trail.covers``).

When it fires it recommends zero linear velocity and a turn in place that swings the
direction of travel toward the freer side (``safety_turn_rps``): the robot recovers instead
of freezing with an obstacle in front of it forever. Priority 100: above every other
shipped scenario, so nothing overrides it while it is live.

A safety rule of the engine (``safety = True``): in every activation the engine runs every
robot's safety_stop before any other scenario, dwa's heavy decisions included, and never
cuts it by N or F (docs/ENGINE.md, "Safety rules first").
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from common.contract.limits import clamp
from common.contract.records import LaserScan, Odometry, Robot
from common.controller_core.params import number
from common.controller_core.scenario import Command, ControllerScenario
from common.trail import Trail
from services.controller.sectors import ScanView, deg

MOVING_MPS = 0.01  # below this the robot is not translating (odometry noise, creeping)
# How far the freer side is judged: where the robot can go once it has turned.
FREER_HORIZON_M = 1.0
# the cone round the direction of travel the lidar must see into for the robot to move
TRAVEL_CONE_DEG = 30.0
AHEAD = (-deg(TRAVEL_CONE_DEG), deg(TRAVEL_CONE_DEG))
BEHIND = (deg(180.0 - TRAVEL_CONE_DEG), deg(180.0 + TRAVEL_CONE_DEG))


@dataclass(frozen=True)
class SafetyParams:
    margin_m: float = 0.06
    lookahead_s: float = 0.2
    turn_rps: float = 0.8

    @classmethod
    def read(cls, params: Mapping[str, Any]) -> SafetyParams:
        d = cls()
        return cls(
            margin_m=number(params, "safety_margin_m", d.margin_m, high=2.0),
            lookahead_s=number(params, "safety_lookahead_s", d.lookahead_s, high=5.0),
            turn_rps=number(params, "safety_turn_rps", d.turn_rps, high=100.0),
        )


class SafetyStop(ControllerScenario):
    scenario = "safety_stop"
    priority = 100
    needs_odometry = True
    safety = True  # runs first in each activation, uncut (docs/ENGINE.md)

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.trail = Trail()  # the robot's poses at each scan judged: the way back it knows

    def judge(self, scan: LaserScan, odom: Odometry | None) -> Command | None:
        if odom is not None:
            self.trail.note(odom.stamp, odom.x, odom.y, odom.yaw)
        spec = self.spec
        return self.decide(scan, odom, spec.robot, spec.params, self.trail)

    @classmethod
    def decide(
        cls,
        scan: LaserScan,
        odom: Odometry | None,
        robot: Robot,
        params: Mapping[str, Any],
        trail: Trail | None = None,
    ) -> Command | None:
        """``trail``: the robot's recent poses; a blind move that retraces them passes."""
        p = SafetyParams.read(params)
        view = ScanView.of(scan)
        stop_m = robot.footprint_radius_m + p.margin_m
        linear = odom.linear_mps if odom is not None else 0.0
        if abs(linear) <= MOVING_MPS:
            if view.boxed_in(stop_m):
                return Command(0.0, 0.0, f"boxed in: obstacles within {stop_m:.2f} m all around")
            return None
        direction = 1 if linear > 0 else -1
        reach_m = stop_m + abs(linear) * p.lookahead_s + robot.braking_m(linear)
        way = "forward" if direction > 0 else "backward"
        if not view.sees(AHEAD if direction > 0 else BEHIND):
            if odom is not None and trail is not None and _retraced(trail, odom, robot, p):
                return None  # where the outline just was: clear a moment ago
            return Command(
                0.0,
                0.0,
                f"moving {way} at {abs(linear):.2f} m/s blind: the lidar has no beams "
                f"within {TRAVEL_CONE_DEG:g} deg of the way: stop",
            )
        hit = view.swept(direction, robot.footprint_radius_m, reach_m)
        if not hit.found:
            return None
        turn = clamp(p.turn_rps, robot.max_angular_rps)
        if direction > 0:
            # A positive (counter-clockwise) turn swings the front toward the left.
            toward_left = view.left_is_freer((0.0, deg(90)), (-deg(90), 0.0), FREER_HORIZON_M)
            angular, side = (turn, "left") if toward_left else (-turn, "right")
        else:
            # A positive turn swings the back toward the back-right.
            back_right_freer = not view.left_is_freer(
                (deg(90), deg(180)), (-deg(180), -deg(90)), FREER_HORIZON_M
            )
            angular, side = (turn, "back-right") if back_right_freer else (-turn, "back-left")
        return Command(
            0.0,
            angular,
            f"moving {way} at {abs(linear):.2f} m/s: obstacle {hit.describe()} within "
            f"{reach_m:.2f} m (footprint {robot.footprint_radius_m:.3f} + margin "
            f"{p.margin_m:.2f} + look-ahead + braking): stop, turn toward the freer {side}",
        )


def _retraced(trail: Trail, odom: Odometry, robot: Robot, p: SafetyParams) -> bool:
    """Whether the footprint polygon, moving on as measured for its look-ahead and braking,
    stays within where its outline was along the trail (a disc's blind side is
    never judged so: it turns in place to see)."""
    footprint = robot.footprint
    if footprint.is_disc:
        return False
    speed = abs(odom.linear_mps)
    # the trail's own cover is the margin (1 cm beyond where the outline was); a bend in
    # it is judged at the next scan, with the turn rate measured then (the measured turn
    # lags the one commanded: judged farther on, a retrace changing its curvature stopped)
    distance = speed * p.lookahead_s + robot.braking_m(speed)
    pose = (odom.x, odom.y, odom.yaw)
    return trail.covers(footprint, pose, odom.linear_mps, odom.angular_rps, distance)

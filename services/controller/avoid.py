"""What avoid_left and avoid_right share: one decision, so they never contradict each other.

The thesis' controller (section 5, ``actions Controller``) compares a few beams with
OBJ_DISTANCE and turns away from the side that is too close. Here, with the default params:

- the *front-right* sector is -60 to -5 deg, the *front-left* 5 to 60 deg, the *dead-ahead*
  cone -5 to 5 deg (angles counter-clockwise from the heading);
- a beam counts as an obstacle when it is closer than ``avoid_distance_m`` (footprint radius
  + 0.295 m: 0.40 m for the Burger) *and* its lateral offset from the robot's line of
  travel, range x |sin(angle)|, is below ``avoid_lateral_m`` (footprint radius + 0.145 m:
  0.25 m for the Burger): something in or near the robot's way. A wall the robot is
  merely passing (in the middle of an aisle 0.9 m wide or more, heading along it, the walls
  are 0.45 m to either side) does not count, so the robot is not pushed off its path in
  every aisle; an unmapped pallet or crate ahead still does;
- an obstacle only on the front-right: turn left (avoid_left); only on the front-left: turn
  right (avoid_right);
- dead ahead, or on both sides at once: turn toward the freer half, where the closer closest
  obstacle loses, then the less open half, then (a perfect tie) left. :func:`decide_turn`
  computes this once for both scenarios, so exactly one of them recommends: never a left and a
  right of equal priority that would leave the robot to whichever the decision saw last.

The recommendation: ``avoid_angular_rps`` toward the chosen side, forward at
``avoid_linear_mps``, or turning in place when the obstacle is nearer than
``avoid_stop_distance_m`` (footprint radius + 0.095 m: 0.20 m for the Burger); both clamped
to the robot's limits. The distances' defaults follow the robot row's footprint, so a bigger
robot keeps the same clearances; a strategy's params may set them outright.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

from common.contract.limits import clamp
from common.contract.records import LaserScan, Odometry, Robot
from common.controller_core.params import number
from common.controller_core.scenario import Command, ControllerScenario
from services.controller.sectors import Hit, ScanView, Sector, deg, describe_sector

LEFT, RIGHT = 1, -1


# the default distances beyond the robot's footprint radius (the row's), m
DISTANCE_BEYOND_M = 0.295
LATERAL_BEYOND_M = 0.145
STOP_BEYOND_M = 0.095


@dataclass(frozen=True)
class AvoidParams:
    distance_m: float
    lateral_m: float
    stop_distance_m: float
    sector_deg: float = 60.0
    front_deg: float = 5.0
    linear_mps: float = 0.05
    angular_rps: float = 1.0

    @classmethod
    def defaults(cls, footprint_m: float) -> AvoidParams:
        """The defaults for a robot of footprint radius ``footprint_m`` (to the micrometre:
        the Burger's are exactly 0.40, 0.25 and 0.20 m)."""
        return cls(
            distance_m=round(footprint_m + DISTANCE_BEYOND_M, 6),
            lateral_m=round(footprint_m + LATERAL_BEYOND_M, 6),
            stop_distance_m=round(footprint_m + STOP_BEYOND_M, 6),
        )

    @classmethod
    def read(cls, params: Mapping[str, Any], footprint_m: float) -> AvoidParams:
        d = cls.defaults(footprint_m)
        sector = number(params, "avoid_sector_deg", d.sector_deg, low=1.0, high=180.0)
        return cls(
            distance_m=number(params, "avoid_distance_m", d.distance_m, high=10.0),
            lateral_m=number(params, "avoid_lateral_m", d.lateral_m, high=10.0),
            sector_deg=sector,
            front_deg=number(params, "avoid_front_deg", d.front_deg, high=sector),
            linear_mps=number(params, "avoid_linear_mps", d.linear_mps, high=10.0),
            angular_rps=number(params, "avoid_angular_rps", d.angular_rps, high=100.0),
            stop_distance_m=number(params, "avoid_stop_distance_m", d.stop_distance_m, high=10.0),
        )


@dataclass(frozen=True)
class Turn:
    """Which way to turn, and the obstacle and sector that call for it."""

    side: int  # LEFT (counter-clockwise, positive angular) or RIGHT
    hit: Hit
    where: str  # for the reason, e.g. "front-right [-60, -5] deg"


def decide_turn(view: ScanView, p: AvoidParams) -> Turn | None:
    outer, inner = deg(p.sector_deg), deg(p.front_deg)
    right_sector: Sector = (-outer, -inner)
    left_sector: Sector = (inner, outer)
    ahead_sector: Sector = (-inner, inner)
    band = (p.distance_m, p.lateral_m)
    right, left = view.closest(right_sector, *band), view.closest(left_sector, *band)
    ahead = view.closest(ahead_sector, *band)
    near_right, near_left, near_ahead = right.found, left.found, ahead.found
    if near_ahead or (near_right and near_left):
        freer_left = view.left_is_freer((0.0, outer), (-outer, 0.0), horizon_m=2 * p.distance_m)
        hit = min((ahead, right, left), key=lambda h: h.range_m)
        where = f"dead ahead {describe_sector(ahead_sector)}" if near_ahead else "on both sides"
        freer = "left" if freer_left else "right"
        return Turn(LEFT if freer_left else RIGHT, hit, f"{where} (the {freer} half is freer)")
    if near_right:
        return Turn(LEFT, right, f"front-right {describe_sector(right_sector)}")
    if near_left:
        return Turn(RIGHT, left, f"front-left {describe_sector(left_sector)}")
    return None


def turn_for(view: ScanView, p: AvoidParams) -> Turn | None:
    """:func:`decide_turn`, once per scan and params: avoid_left and avoid_right both ask."""
    key = (decide_turn, p)
    if key not in view.memo:
        view.memo[key] = decide_turn(view, p)
    turn: Turn | None = view.memo[key]  # type: ignore[assignment]
    return turn


class AvoidScenario(ControllerScenario):
    """avoid_left or avoid_right: recommends only when :func:`decide_turn` picks its side."""

    side: ClassVar[int] = LEFT
    priority = 50

    @classmethod
    def decide(
        cls, scan: LaserScan, odom: Odometry | None, robot: Robot, params: Mapping[str, Any]
    ) -> Command | None:
        p = AvoidParams.read(params, robot.footprint_radius_m)
        turn = turn_for(ScanView.of(scan), p)
        if turn is None or turn.side != cls.side:
            return None
        close = turn.hit.range_m < p.stop_distance_m
        linear = 0.0 if close else clamp(p.linear_mps, robot.max_linear_mps)
        angular = cls.side * clamp(p.angular_rps, robot.max_angular_rps)
        action = "turn in place" if close else "slow down and turn"
        direction = "left" if cls.side == LEFT else "right"
        return Command(
            linear,
            angular,
            f"obstacle {turn.hit.describe()} {turn.where}, closer than "
            f"{p.distance_m:.2f} m and within {p.lateral_m:.2f} m of the way ahead: "
            f"{action} {direction}",
        )

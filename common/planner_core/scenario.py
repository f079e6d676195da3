"""The base of every planner move scenario: how a heading error becomes a velocity.

A move scenario says only that, in :meth:`MoveScenario.select`, from the heading error to
the route's steering point, the distance left, the robot (its limits) and its measured turn
rate. The rest is the planner's, the same for every scenario (services/planner/scenario.py,
docs/PLANNER.md): the target, the A* route to it, reaching it or failing it, the cadence of
recommendations and writing them. The planner makes each scenario class found under the
entry-point group :data:`SCENARIO_GROUP` into one rule per robot (a subclass of both the
scenario and its own rule), so the rule carries the scenario's name in logs and
engine_stats, and ``self`` in ``select`` is that rule.

This module lives in common/ so that a scenario package needs nothing of the planner
service's: neither its grids and routes nor its store.
"""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass
from typing import ClassVar

from common.contract.limits import clamp as clamp  # the plug-in interface's clamp
from common.footprint import Footprinted, Polygon

# The entry-point group that names the move scenarios (name = a strategy's planner_scenario).
SCENARIO_GROUP = "pnav.planner.scenarios"

SLOW_RADIUS_M = 0.6  # closer than this to the target: slow down in proportion
MIN_SPEED_FRACTION = 0.25  # ...but never below this fraction of max_linear


@dataclass(frozen=True)
class Movement:
    """What a scenario selects: a velocity, and whether it turns in place (rather than
    drives), which the planner keeps as ``turning`` and weighs when deciding to write."""

    linear: float
    angular: float
    turning: bool  # turning in place (turn_then_move) rather than driving


@dataclass(frozen=True)
class RobotInfo(Footprinted):
    """A robot as the planner reads it (its robot row): what ``select`` sees of it."""

    robot_id: str
    world: str | None
    max_linear_mps: float
    max_angular_rps: float
    footprint_radius_m: float
    # the row's footprint_polygon (robot frame, counter-clockwise); None: the disc
    footprint_polygon: Polygon | None = None


class MoveScenario:
    """A planner move scenario: subclasses set ``scenario`` and say, in ``select``, how a
    heading error becomes a velocity."""

    scenario: ClassVar[str] = ""
    # The planner sets this after each recommendation: the robot was last told to turn in
    # place (``Movement.turning``). A scenario with hysteresis reads it (turn_then_move).
    turning: bool = False

    @abstractmethod
    def select(
        self, error: float, remaining_m: float, info: RobotInfo, turn_rate: float = 0.0
    ) -> Movement:
        """The velocity for a heading error (rad, CCW positive), the distance left and the
        measured turn rate (rad/s, from the odometry)."""


def cruise_speed(max_linear: float, remaining_m: float) -> float:
    """Full speed, slowing down over the last SLOW_RADIUS_M so the robot does not overshoot."""
    fraction = min(1.0, max(MIN_SPEED_FRACTION, remaining_m / SLOW_RADIUS_M))
    return max_linear * fraction

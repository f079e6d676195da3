"""Arriving at a pose: the final turn in place to a heading, and standing still before a
pose counts as reached.

Once the robot's centre is within a target's tolerance, a target with a heading (a goal's or
a waypoint's ``yaw``) is turned to in place, and one with a heading or a halt on a route
must also see the robot stand (turn rate and speed settled) before it is reached: a robot
still turning when its heading first comes within the tolerance would otherwise be called
there and sweep past. The same for every move scenario and strategy: the planner says it
whatever scenario drives (GOTO_FAST's local controller stops on the empty path).

The turn is turn_then_move's (proportional to the error anticipated ANTICIPATE_S ahead,
fine near the heading), with a floor that a loop delay of 0.2 s cannot carry past the
tolerance: ``2 x yaw_tol`` rad/s, within [MIN_FINAL_RPS, MIN_TURN_RPS]. Pure.
"""

from __future__ import annotations

import math

from common.planner_core.scenario import Movement
from services.planner.routes import Target
from services.planner.tracking import wrap_angle
from services.planner.turn_then_move import (
    ANTICIPATE_S,
    FINE_RAD,
    FINE_TURN_RPS,
    MAX_TURN_RPS,
    MIN_TURN_RPS,
    TURN_GAIN,
)

SETTLED_RPS = 0.05  # the robot stands when it turns slower than this...
SETTLED_MPS = 0.02  # ...and drives slower than this
MIN_FINAL_RPS = 0.05  # the final turn never slower than this
# While turning or settling at a target, the position still holds this much beyond its
# tolerance (a turn in place drifts a little): the robot does not drive off and come back.
ALIGN_SLACK_M = 0.05
STOP = Movement(0.0, 0.0, True)


def heading_error(target: Target, yaw: float) -> float:
    """The turn left (CCW positive) from ``yaw`` to the target's heading (0 without one)."""
    return 0.0 if target.yaw is None else wrap_angle(target.yaw - yaw)


def final_turn_speed(error: float, turn_rate: float, max_angular: float, tol: float) -> float:
    """The signed turn-in-place rate toward a heading ``error`` away."""
    ahead = error - turn_rate * ANTICIPATE_S
    floor = max(MIN_FINAL_RPS, min(MIN_TURN_RPS, 2.0 * tol))
    cap = min(max_angular, FINE_TURN_RPS if abs(error) < FINE_RAD else MAX_TURN_RPS)
    magnitude = max(floor, TURN_GAIN * abs(ahead) if ahead * error > 0 else 0.0)
    return math.copysign(min(cap, magnitude), error)


def final_move(
    target: Target, yaw: float, turn_rate: float, linear: float, max_angular: float
) -> Movement | None:
    """At the target's position: the turn to its heading, a stop to settle, or None when
    the pose holds and the robot stands (reached)."""
    error = heading_error(target, yaw)
    if abs(error) > target.yaw_tol:
        return Movement(0.0, final_turn_speed(error, turn_rate, max_angular, target.yaw_tol), True)
    if abs(turn_rate) > SETTLED_RPS or abs(linear) > SETTLED_MPS:
        return STOP
    return None


def at_position(target: Target, distance: float, aligning: bool) -> bool:
    """Whether the robot counts as at the target's position (``aligning``: it was already,
    and is turning or settling there)."""
    return distance <= target.reach_m + (ALIGN_SLACK_M if aligning else 0.0)


def why(target: Target, move: Movement, yaw: float) -> str:
    """The reason of a final-turn recommendation, for people."""
    error = heading_error(target, yaw)
    if move.angular != 0.0:
        return (
            f"at {target.label}: turning to its heading, error {error:.2f} rad "
            f"(tolerance {target.yaw_tol:.2f})"
        )
    return f"at {target.label}: stopping to stand, heading error {error:.2f} rad"

"""turn_then_move: the thesis' selectMovement. Turn in place toward the path, then drive.

While the heading error to the steering point exceeds THRESHOLD_RAD the robot turns in place
(proportional, capped at the robot's max, never slower than MIN_TURN_RPS so it cannot stall
short of the threshold); otherwise it drives forward with a small proportional heading
correction. Hysteresis: once turning it keeps turning until the error is below half the
threshold, so a robot hovering at the threshold does not chatter between the two.
"""

from __future__ import annotations

import math

from services.planner.scenario import Movement, MoveScenario, clamp, cruise_speed
from services.planner.state import RobotInfo

THRESHOLD_RAD = 0.3
TURN_GAIN = 1.5  # rad/s per rad of heading error, turning in place
MIN_TURN_RPS = 0.3
HEADING_GAIN = 1.2  # rad/s per rad, correcting the heading while driving


def select_movement(
    error: float,
    remaining_m: float,
    max_linear: float,
    max_angular: float,
    turning: bool = False,
    threshold: float = THRESHOLD_RAD,
) -> Movement:
    """Turn left (positive angular) for a positive error, right for a negative one, drive
    forward when the steering point is within the threshold of straight ahead."""
    limit = threshold / 2 if turning else threshold
    if abs(error) > limit:
        speed = min(max_angular, max(MIN_TURN_RPS, TURN_GAIN * abs(error)))
        return Movement(0.0, math.copysign(speed, error), True)
    linear = cruise_speed(max_linear, remaining_m)
    return Movement(linear, clamp(HEADING_GAIN * error, max_angular), False)


class TurnThenMove(MoveScenario):
    scenario = "turn_then_move"

    def select(self, error: float, remaining_m: float, info: RobotInfo) -> Movement:
        return select_movement(
            error, remaining_m, info.max_linear_mps, info.max_angular_rps, self.turning
        )

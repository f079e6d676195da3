"""move_while_turning: drive and turn at once, the second planner scenario of the thesis.

The angular speed is proportional to the heading error; the linear speed is the cruise speed
scaled by cos(error), floored at zero, so the robot slows through sharp turns, turns on the
spot when the path is behind it, and never drives backward.
"""

from __future__ import annotations

import math

from services.planner.scenario import Movement, MoveScenario, clamp, cruise_speed
from services.planner.state import RobotInfo

TURN_GAIN = 1.5  # rad/s per rad of heading error


def select_movement(
    error: float, remaining_m: float, max_linear: float, max_angular: float
) -> Movement:
    linear = cruise_speed(max_linear, remaining_m) * max(0.0, math.cos(error))
    return Movement(linear, clamp(TURN_GAIN * error, max_angular), linear == 0.0)


class MoveWhileTurning(MoveScenario):
    scenario = "move_while_turning"

    def select(self, error: float, remaining_m: float, info: RobotInfo) -> Movement:
        return select_movement(error, remaining_m, info.max_linear_mps, info.max_angular_rps)

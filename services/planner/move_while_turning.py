"""move_while_turning: drive and turn at once, the second planner scenario of the thesis.

The angular speed is proportional to the heading error (capped at MAX_TURN_RPS, a rate the
loop's delay cannot make it overshoot by much); the linear speed is the cruise speed scaled
by cos(error), floored at zero, so the robot slows through sharp turns, turns on the spot
when the path is behind it, and never drives backward.
"""

from __future__ import annotations

import math

from common.planner_core.scenario import Movement, MoveScenario, RobotInfo, clamp, cruise_speed

TURN_GAIN = 1.2  # rad/s per rad of heading error
MAX_TURN_RPS = 1.5


def select_movement(
    error: float, remaining_m: float, max_linear: float, max_angular: float
) -> Movement:
    linear = cruise_speed(max_linear, remaining_m) * max(0.0, math.cos(error))
    angular = clamp(TURN_GAIN * error, min(max_angular, MAX_TURN_RPS))
    return Movement(linear, angular, linear == 0.0)


class MoveWhileTurning(MoveScenario):
    scenario = "move_while_turning"

    def select(
        self, error: float, remaining_m: float, info: RobotInfo, turn_rate: float = 0.0
    ) -> Movement:
        return select_movement(error, remaining_m, info.max_linear_mps, info.max_angular_rps)

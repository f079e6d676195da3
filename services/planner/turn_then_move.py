"""turn_then_move: the thesis' selectMovement. Turn in place toward the path, then drive.

While the heading error to the steering point exceeds THRESHOLD_RAD the robot turns in place;
otherwise it drives forward with a small proportional heading correction. Once turning, it
keeps turning until the error is below ALIGNED_RAD (hysteresis), so a robot hovering at the
threshold does not chatter between the two.

The turn is made robust to the loop's delay: between an odometry row and the wheels obeying
the command it leads to, the robot keeps turning at its old rate, for 0.1 s of sim time or
(at an accelerated sim on a loaded machine) half a second. So:

- the turn rate is proportional to the error *anticipated* that much later (the error minus
  the measured turn rate x ANTICIPATE_S), with a modest gain, capped at MAX_TURN_RPS and at
  FINE_TURN_RPS once the error is below FINE_RAD, so the robot slows down well before the
  target heading instead of sweeping past it;
- the turn ends as soon as the anticipated error is below ALIGNED_RAD (or past zero): what
  the robot still turns after that, it turns toward the target heading, and the heading
  correction while driving takes care of the rest;
- the rate never falls below MIN_TURN_RPS, so the robot cannot stall short of the end.
"""

from __future__ import annotations

import math

from common.planner_core.scenario import Movement, MoveScenario, RobotInfo, clamp, cruise_speed

THRESHOLD_RAD = 0.3  # turn in place above this heading error
ALIGNED_RAD = 0.15  # ...until the error is below this
TURN_GAIN = 1.5  # rad/s per rad of anticipated heading error, turning in place
MIN_TURN_RPS = 0.3
MAX_TURN_RPS = 2.0
FINE_RAD = 0.5  # closer than this to the target heading, turn at most...
FINE_TURN_RPS = 0.6  # ...this fast
ANTICIPATE_S = 0.4  # how far ahead (s) the heading error is anticipated
HEADING_GAIN = 1.0  # rad/s per rad, correcting the heading while driving
MAX_HEADING_RPS = 0.6  # cap on that correction


def anticipated(error: float, turn_rate: float) -> float:
    """The heading error ANTICIPATE_S from now if the robot keeps turning at ``turn_rate``."""
    return error - turn_rate * ANTICIPATE_S


def turn_speed(error: float, turn_rate: float, max_angular: float) -> float:
    """The signed turn-in-place rate for a heading ``error``, given the measured rate."""
    ahead = anticipated(error, turn_rate)
    cap = min(max_angular, FINE_TURN_RPS if abs(error) < FINE_RAD else MAX_TURN_RPS)
    magnitude = max(MIN_TURN_RPS, TURN_GAIN * abs(ahead) if ahead * error > 0 else 0.0)
    return math.copysign(min(cap, magnitude), error)


def select_movement(
    error: float,
    remaining_m: float,
    max_linear: float,
    max_angular: float,
    turning: bool = False,
    threshold: float = THRESHOLD_RAD,
    turn_rate: float = 0.0,
) -> Movement:
    """Turn left (positive angular) for a positive error, right for a negative one, drive
    forward when the steering point is within the threshold of straight ahead.

    ``turning``: the robot was turning in place (hysteresis). ``turn_rate``: its measured
    angular velocity (odometry), to anticipate where the turn will have got to."""
    ahead = anticipated(error, turn_rate)
    if turning:
        # Until aligned, unless the turn still under way will sweep well past the target
        # heading anyway (a long loop delay): then the heading correction brakes it.
        overshooting = ahead * error < 0 and abs(ahead) > ALIGNED_RAD
        keep_turning = abs(error) > ALIGNED_RAD and not overshooting
    else:
        # Both the error and the anticipated one: a robot still turning toward the target
        # heading (the loop's delay) does not start turning in place again.
        keep_turning = abs(error) > threshold and ahead * error > 0 and abs(ahead) > threshold
    if keep_turning:
        return Movement(0.0, turn_speed(error, turn_rate, max_angular), True)
    linear = cruise_speed(max_linear, remaining_m)
    correction = clamp(
        HEADING_GAIN * anticipated(error, turn_rate), min(max_angular, MAX_HEADING_RPS)
    )
    return Movement(linear, correction, False)


class TurnThenMove(MoveScenario):
    scenario = "turn_then_move"

    def select(
        self, error: float, remaining_m: float, info: RobotInfo, turn_rate: float = 0.0
    ) -> Movement:
        return select_movement(
            error,
            remaining_m,
            info.max_linear_mps,
            info.max_angular_rps,
            self.turning,
            turn_rate=turn_rate,
        )

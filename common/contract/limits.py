"""The bounds migration 3 of the contract enforces, for code that wants to refuse first.

schema.sql is the authority (its CHECK constraints); these mirror it so that a tool can say
why a value is refused before the database does (tests/contract/test_refused_values.py
checks both agree at every bound). CONTRACT.md, "Refused values", says why each is what it is.
"""

from __future__ import annotations

import math
from typing import Final

from common.errors import ContractError

# goal: x and y within +-100 km of the world origin (the bridge refuses odometry beyond it,
# so a goal further away could never be reached); tolerance in (0, 100] m.
GOAL_MAX_ABS_M: Final = 1.0e5
GOAL_MAX_TOLERANCE_M: Final = 100.0

# command_recommendation and command2robot velocities.
MAX_ABS_LINEAR_MPS: Final = 10.0
MAX_ABS_ANGULAR_RPS: Final = 20.0

# command_recommendation.priority; from SAFETY_PRIORITY up only stops (linear_mps = 0).
MIN_PRIORITY: Final = 0
MAX_PRIORITY: Final = 1000
SAFETY_PRIORITY: Final = 100

# strategy.params: top-level numbers within +-this.
MAX_ABS_PARAM: Final = 1.0e6


def check_goal(x: float, y: float, tolerance_m: float | None) -> None:
    """ContractError naming the first value the goal table would refuse, if any."""
    for name, value in (("x", x), ("y", y)):
        if not (math.isfinite(value) and abs(value) <= GOAL_MAX_ABS_M):
            raise ContractError(
                f"goal {name} must be a finite number of metres within "
                f"+-{GOAL_MAX_ABS_M:.0f}, got {value!r}"
            )
    if tolerance_m is not None and not (
        math.isfinite(tolerance_m) and 0 < tolerance_m <= GOAL_MAX_TOLERANCE_M
    ):
        raise ContractError(
            f"goal tolerance must be a finite number of metres in (0, "
            f"{GOAL_MAX_TOLERANCE_M:.0f}], got {tolerance_m!r}"
        )

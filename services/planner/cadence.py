"""When a move rule's velocity is worth a recommendation: the planner's cadence.

The odometry comes at 30 Hz and most rows change nothing worth a write; a recommendation is
written for a new target, a switch between turning and driving, a material change of
velocity, or RECOMMEND_PERIOD_S of sim time since the last one (services/planner/scenario.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from common.planner_core.scenario import Movement

# Recommend again at least this often (sim s) while nothing changes: well inside VALIDITY_S,
# and as often as the decision service re-issues its winner anyway.
RECOMMEND_PERIOD_S = 0.1
# A velocity differing from the last recommendation by more than this is sent at once.
CHANGE_LINEAR_MPS = 0.02
CHANGE_ANGULAR_RPS = 0.1


@dataclass(frozen=True)
class Said:
    """The last velocity recommended: what a new one is compared with."""

    stamp: float
    target_key: tuple[Any, ...]
    move: Movement


def due(last: Said | None, stamp: float, target_key: tuple[Any, ...], move: Movement) -> bool:
    """Whether ``move`` (for the odometry at ``stamp``) is worth a recommendation: a first one,
    a new target, a switch between turning and driving, a material change of velocity, or
    RECOMMEND_PERIOD_S since the last one (or sim time went back: the sim restarted)."""
    if last is None or last.target_key != target_key or last.move.turning != move.turning:
        return True
    if not last.stamp <= stamp < last.stamp + RECOMMEND_PERIOD_S - 1e-9:
        return True
    return (
        abs(move.linear - last.move.linear) > CHANGE_LINEAR_MPS
        or abs(move.angular - last.move.angular) > CHANGE_ANGULAR_RPS
        or (move.angular == 0.0) != (last.move.angular == 0.0)
    )

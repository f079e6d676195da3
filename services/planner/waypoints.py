"""Routes through waypoints: which pose of a goal's route the robot is driving to now.

A goal with goal_waypoint rows (CONTRACT.md, migration 13) is driven through them in ``seq``
order, then to its own pose. The target is the first waypoint still ``pending`` on its row
and not yet reached in this planner's memory (``done``: its own marks, before the rows say
so), else the goal itself. A waypoint passed through (no ``stop``, no ``yaw``) is reached
once the robot's centre is within its tolerance, and the carrot goes straight on to the next;
the speed slows only toward the next pose the robot halts at (``Target.beyond_m``). Pure.
"""

from __future__ import annotations

import math
from collections.abc import Collection

from common.contract import records
from common.contract.limits import DEFAULT_YAW_TOLERANCE_RAD
from services.planner.routes import Target


def halts(waypoint: records.Waypoint) -> bool:
    """Whether the robot stops at ``waypoint``: it asks to, or it has a heading to turn to."""
    return waypoint.stop or waypoint.yaw is not None


def pending(goal: records.Goal, done: Collection[int]) -> list[records.Waypoint]:
    """The goal's waypoints still to drive through, in order."""
    return [w for w in goal.waypoints if w.status == "pending" and w.seq not in done]


def route_target(goal: records.Goal, done: Collection[int] = ()) -> Target:
    """Where the robot drives now on ``goal``'s route: its first pending waypoint, or the
    goal's own pose once none is left."""
    left = pending(goal, done)
    if not left:
        return Target.of_goal(goal)
    first = left[0]
    beyond = 0.0
    if not halts(first):
        # straight-line length on to the next pose the robot halts at (the goal's at the end)
        here = (first.x, first.y)
        for w in [*left[1:], None]:
            there = (goal.x, goal.y) if w is None else (w.x, w.y)
            beyond += math.hypot(there[0] - here[0], there[1] - here[1])
            if w is None or halts(w):
                break
            here = there
    return Target(
        "goal",
        f"{goal.id}#{first.seq}",
        first.x,
        first.y,
        first.tolerance_m,
        0.0,
        goal.id,
        first.yaw,
        first.yaw_tolerance_rad or DEFAULT_YAW_TOLERANCE_RAD,
        first.seq,
        halts(first),
        beyond,
    )


def failure(target: Target, why: str) -> str:
    """The reason a goal fails for: a waypoint's names it."""
    if target.seq is None:
        return why
    return f"waypoint {target.seq} ({target.x:.2f}, {target.y:.2f}): {why}"

"""Routes through waypoints: which pose of a goal's route the robot is driving to now.

A goal with goal_waypoint rows (CONTRACT.md, migration 13) is driven through them in ``seq``
order, then to its own pose. The target is the first waypoint still ``pending`` on its row
and not yet reached in this planner's memory (``done``: its own marks, before the rows say
so), else the goal itself. A waypoint passed through (no ``stop``, no ``yaw``) is reached
once the robot's centre is within its tolerance, and the carrot goes straight on to the next;
the speed slows only toward the next pose the robot halts at (``Target.beyond_m``).

Every waypoint is also judged ahead of the robot (:func:`check_ahead`): one the map proves
unreachable (reachability.spot_problem: off the map, in or too close to an obstacle) fails
the route as soon as it is looked at, not when the robot gets there. A spot check costs about
a millisecond, so CHECK_AHEAD of them per look: a route of 20 waypoints is judged within
four looks (a quarter of a second), one of 1 000 within 200, while the robot drives. Pure.
"""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import dataclass
from typing import Any

import services.planner.reachability as reachability
from common.contract import records
from common.contract.limits import DEFAULT_YAW_TOLERANCE_RAD
from services.planner.routes import Target
from services.planner.world_model import MapData, inflation_m

CHECK_AHEAD = 5  # waypoints judged against the map per look


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
    return waypoint_target(goal, first, beyond)


def waypoint_target(goal: records.Goal, w: records.Waypoint, beyond: float = 0.0) -> Target:
    """The target of waypoint ``w`` of ``goal``."""
    yaw_tol = w.yaw_tolerance_rad or DEFAULT_YAW_TOLERANCE_RAD
    key = f"{goal.id}#{w.seq}"
    return Target(
        "goal", key, w.x, w.y, w.tolerance_m, 0.0, goal.id, w.yaw, yaw_tol, w.seq, halts(w), beyond
    )


@dataclass
class Ahead:
    """How far a route has been judged against one map: ``key`` (the goal, the map's
    version, the footprint) and the index of the next waypoint to judge."""

    key: tuple[Any, ...]
    checked: int = 0


def check_ahead(
    data: MapData, footprint_m: float, goal: records.Goal, ahead: Ahead, limit: int = CHECK_AHEAD
) -> tuple[records.Waypoint, str] | None:
    """The next ``limit`` pending waypoints not judged yet, judged on the map: the first one
    it proves unreachable, with why (None: none of them)."""
    inflation = inflation_m(footprint_m)
    end = min(len(goal.waypoints), ahead.checked + limit)
    for w in goal.waypoints[ahead.checked : end]:
        ahead.checked += 1
        if w.status != "pending":
            continue
        why = reachability.spot_problem(data, inflation, w.x, w.y, w.tolerance_m)
        if why is not None:
            return w, why
    return None


def failure(target: Target, why: str) -> str:
    """The reason a goal fails for: a waypoint's names it."""
    if target.seq is None:
        return why
    return f"waypoint {target.seq} ({target.x:.2f}, {target.y:.2f}): {why}"

"""The path the planner publishes: one ``planned_path`` row each time a robot's route is
planned or re-planned, and an empty one when the robot has no route any more (CONTRACT.md,
planned_path).

Local controllers score their trajectories against this row (docs/CONTROLLER.md, dwa); the
dashboard and the recorder draw it. The move rule decides *when* (scenario.py): what is
here is *what* the row says, and the key that tells one published path from the next.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from services.planner.routes import Target
from services.planner.tracking import Route

PathRow = dict[
    str, Any
]  # the contract columns of one planned_path row (records.PLANNED_PATH_COLUMNS)
# What a published path was: the Route object it showed (a new plan is a new object), or
# ("empty", target key) for an empty one.
PathKey = Route | tuple[Any, ...]


def _target_columns(target: Target | None) -> dict[str, Any]:
    if target is None:
        return {"goal_id": None, "target": "none", "target_x": None, "target_y": None}
    return {
        "goal_id": target.goal_id,
        "target": target.kind,
        "target_x": target.x,
        "target_y": target.y,
    }


def route_row(robot_id: str, stamp: float, target: Target, route: Route) -> PathRow:
    """The row for a route just planned: its points from where the robot was to the target."""
    points = np.asarray(route.points, dtype=np.float64)
    steps = np.diff(points, axis=0)
    length = float(np.hypot(steps[:, 0], steps[:, 1]).sum()) if len(points) > 1 else 0.0
    return {
        "robot_id": robot_id,
        "stamp": stamp,
        **_target_columns(target),
        "xs": [float(v) for v in points[:, 0]],
        "ys": [float(v) for v in points[:, 1]],
        "length_m": length,
    }


def empty_row(robot_id: str, stamp: float, target: Target | None) -> PathRow:
    """The row saying the planner has no path for the robot: ``target`` reached or failed,
    or no target at all (None)."""
    return {
        "robot_id": robot_id,
        "stamp": stamp,
        **_target_columns(target),
        "xs": [],
        "ys": [],
        "length_m": 0.0,
    }


def empty_key(target: Target | None) -> tuple[Any, ...]:
    return ("empty", target.key if target is not None else None)

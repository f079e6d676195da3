"""What the page draws, as JSON-ready dicts built from contract rows (or row images).

Pure functions, no I/O: the store feeds them rows, the page draws what they return. Every
value is a plain number, string, bool, list or dict, finite (JSON has no NaN).
"""

from __future__ import annotations

import base64
import math
from collections.abc import Mapping, Sequence
from typing import Any

Row = Mapping[str, Any]

# lidar points are sent to the centimetre: finer is below the sensor's noise (0.01 m)
_POINT_DIGITS = 2


def _num(value: Any, digits: int = 4) -> float | None:
    """A finite float rounded for the wire, or None (NULL, NaN, infinity)."""
    if value is None:
        return None
    number = float(value)
    return round(number, digits) if math.isfinite(number) else None


def lidar_points(scan: Row, pose: Row) -> list[float]:
    """The scan's hits in the world frame, flattened ``[x0, y0, x1, y1, ...]``.

    Beam i points at ``yaw + angle_min + i * angle_increment`` from the robot's centre (the
    lidar sits on the centre of the shipped robot); ``inf`` (nothing within range) and
    ranges outside ``[range_min, range_max]`` are not hits, so they are left out.
    """
    x0, y0, yaw = float(pose["x"]), float(pose["y"]), float(pose["yaw"])
    start, step = float(scan["angle_min"]), float(scan["angle_increment"])
    low, high = float(scan["range_min"]), float(scan["range_max"])
    points: list[float] = []
    for i, r in enumerate(scan["ranges"] or ()):
        if r is None or not math.isfinite(r) or not low <= r < high:
            continue
        angle = yaw + start + i * step
        points.append(round(x0 + r * math.cos(angle), _POINT_DIGITS))
        points.append(round(y0 + r * math.sin(angle), _POINT_DIGITS))
    return points


def world_map(row: Row | None) -> dict[str, Any] | None:
    """The occupancy grid: geometry, and the cells as base64 (row 0 at the bottom)."""
    if row is None:
        return None
    grid = bytes(row["grid"] or b"")
    return {
        "map_id": row["map_id"],
        "resolution": _num(row["resolution_m"], 6),
        "origin": [_num(row["origin_x"]), _num(row["origin_y"]), _num(row["origin_yaw"])],
        "width": int(row["width"]),
        "height": int(row["height"]),
        "grid": base64.b64encode(grid).decode("ascii"),
    }


def charger(row: Row) -> dict[str, Any]:
    return {
        "id": row["station_id"],
        "x": _num(row["x"]),
        "y": _num(row["y"]),
        "radius_m": _num(row["radius_m"]),
    }


def robot_limits(row: Row) -> dict[str, Any]:
    return {
        "model": row["model"],
        "footprint_m": _num(row["footprint_radius_m"]),
        "max_linear_mps": _num(row["max_linear_mps"]),
        "lidar_range_max_m": _num(row.get("lidar_range_max_m")),
    }


def pose(row: Row) -> dict[str, Any]:
    return {
        "id": row["id"],
        "stamp": _num(row["stamp"]),
        "x": _num(row["x"]),
        "y": _num(row["y"]),
        "yaw": _num(row["yaw"]),
        "linear": _num(row["linear_mps"]),
        "angular": _num(row["angular_rps"]),
    }


def battery(row: Row) -> dict[str, Any]:
    return {
        "stamp": _num(row["stamp"]),
        "percentage": _num(row["percentage"], 2),
        "energy_wh": _num(row["energy_wh"]),
        "charging": bool(row["charging"]),
        "power_w": _num(row["power_w"], 3),
    }


def strategy_state(row: Row) -> dict[str, Any]:
    return {
        "code": row["strategy_code"],
        "resume_code": row["resume_code"],
        "source": row["source"],
        "command_id": row["command_id"],
    }


def goal(row: Row) -> dict[str, Any]:
    return {
        "id": row["id"],
        "x": _num(row["x"]),
        "y": _num(row["y"]),
        "tolerance_m": _num(row["tolerance_m"]),
        "yaw": _num(row.get("yaw")),
        "yaw_tolerance_rad": _num(row.get("yaw_tolerance_rad")),
        "status": row["status"],
        "reason": row["reason"],
    }


def waypoint(row: Row) -> dict[str, Any]:
    """A goal_waypoint row: a pose of a route and its progress."""
    return {
        "seq": row["seq"],
        "x": _num(row["x"]),
        "y": _num(row["y"]),
        "tolerance_m": _num(row["tolerance_m"]),
        "yaw": _num(row["yaw"]),
        "stop": bool(row["stop"]),
        "status": row["status"],
        "reason": row["reason"],
        "reached_stamp": _num(row["reached_stamp"]),
    }


def path(row: Row) -> dict[str, Any]:
    xs, ys = row["xs"] or [], row["ys"] or []
    return {
        "id": row["id"],
        "stamp": _num(row["stamp"]),
        "target": row["target"],
        "goal_id": row.get("goal_id"),
        "xs": [_num(v, 3) for v in xs],
        "ys": [_num(v, 3) for v in ys],
        "length_m": _num(row["length_m"], 3),
    }


def recommendation(row: Row) -> dict[str, Any]:
    return {
        "id": row["id"],
        "kind": row["kind"],
        "source": row["source"],
        "priority": row["priority"],
        "linear": _num(row.get("linear_mps")),
        "angular": _num(row.get("angular_rps")),
        "system_command": row.get("system_command"),
        "stamp": _num(row["stamp"]),
        "expires_stamp": _num(row["expires_stamp"]),
        "reason": row["reason"],
        "inputs": jsonable(row.get("inputs") or {}),
    }


def decision(row: Row, weighed: Sequence[Row]) -> dict[str, Any]:
    """A command2robot row with the recommendations it considered (highest priority first)."""
    ranked = sorted(weighed, key=lambda r: (-int(r["priority"]), -int(r["id"])))
    return {
        "id": row["id"],
        "stamp": _num(row["stamp"]),
        "linear": _num(row["linear_mps"]),
        "angular": _num(row["angular_rps"]),
        "source": row["source"],
        "reason": row["reason"],
        "recommendation_id": row["recommendation_id"],
        "considered_ids": list(row["considered_ids"] or []),
        "considered": [recommendation(r) for r in ranked],
        "safety": row.get("safety"),
    }


def strategy(row: Row) -> dict[str, Any]:
    """A strategy row; params the contract's bounds refuse (``readable`` false: a row older
    than migration 11) are not sent, and the strategy says it is unreadable."""
    readable = row.get("readable", True) is not False
    return {
        "code": row["code"],
        "planner_scenario": row["planner_scenario"],
        "controller_scenarios": list(row["controller_scenarios"] or []),
        "params": jsonable(row["params"]) if readable else None,
        "description": row["description"],
        "unreadable": None if readable else UNREADABLE_PARAMS,
    }


UNREADABLE_PARAMS = (
    "params beyond the contract's bounds (nested too deep, too large, or a number beyond "
    "64 bits): not shown; CONTRACT.md, Refused values"
)
# deeper than this, jsonable gives a mark instead of the value: what the page shows comes
# from rows anyone may have written, and a recursive walk must stay far from Python's limit
MAX_DEPTH = 32
TOO_DEEP = f"(nested deeper than {MAX_DEPTH}: not shown)"


def jsonable(value: Any, depth: int = 0) -> Any:
    """``value`` with every non-finite float turned into None (JSON has no NaN), and what
    lies deeper than :data:`MAX_DEPTH` replaced by :data:`TOO_DEEP`."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping | list | tuple) and depth >= MAX_DEPTH:
        return TOO_DEEP
    if isinstance(value, Mapping):
        return {str(k): jsonable(v, depth + 1) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v, depth + 1) for v in value]
    return value

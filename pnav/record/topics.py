"""Contract rows as Foxglove messages: the topics of a recording, and their schemas.

Every message's ``timestamp`` and log time is **sim time** (the row's ``stamp``, seconds,
as nanoseconds from 0), so Foxglove's timeline is the mission's. Frames: ``map`` is the world
frame (the map's and odometry's); ``{robot}/base_link`` is each robot's, placed by ``/tf``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from foxglove.messages import (
    Color,
    CylinderPrimitive,
    FrameTransform,
    FrameTransforms,
    Grid,
    LaserScan,
    Log,
    LogLevel,
    PackedElementField,
    PackedElementFieldNumericType,
    Pose,
    PoseInFrame,
    PosesInFrame,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    Timestamp,
    Vector2,
    Vector3,
)

Row = Mapping[str, Any]
WORLD_FRAME = "map"

# topic (``{robot}`` per robot) -> schema name: the table docs/RECORDING.md shows
TOPICS: dict[str, str] = {
    "/map": "foxglove.Grid",
    "/charging_stations": "foxglove.SceneUpdate",
    "/tf": "foxglove.FrameTransforms",
    "/{robot}/pose": "foxglove.PoseInFrame",
    "/{robot}/scan": "foxglove.LaserScan",
    "/{robot}/path": "foxglove.PosesInFrame",
    "/{robot}/goal": "foxglove.PoseInFrame",
    "/{robot}/decisions": "foxglove.Log",
    "/{robot}/events": "foxglove.Log",
    "/{robot}/recommendations": "pnav.CommandRecommendation",
    "/{robot}/battery": "pnav.Battery",
}


def base_link(robot: str) -> str:
    return f"{robot}/base_link"


def nanos(stamp: float) -> int:
    """Sim seconds -> integer nanoseconds (never negative: MCAP times are unsigned)."""
    return max(0, round(stamp * 1e9))


def timestamp(stamp: float) -> Timestamp:
    ns = nanos(stamp)
    return Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)


def yaw_quaternion(yaw: float) -> Quaternion:
    return Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0))


def pose(x: float, y: float, yaw: float = 0.0) -> Pose:
    return Pose(position=Vector3(x=x, y=y, z=0.0), orientation=yaw_quaternion(yaw))


def map_grid(row: Row, stamp: float) -> Grid:
    """The ``map`` row: one uint8 field ``occupancy``, the contract's values (0 free, 100
    occupied, 255 unknown), row 0 at the origin, as the column says."""
    width, resolution = int(row["width"]), float(row["resolution_m"])
    return Grid(
        timestamp=timestamp(stamp),
        frame_id=WORLD_FRAME,
        pose=pose(float(row["origin_x"]), float(row["origin_y"]), float(row["origin_yaw"])),
        column_count=width,
        cell_size=Vector2(x=resolution, y=resolution),
        row_stride=width,
        cell_stride=1,
        fields=[
            PackedElementField(name="occupancy", offset=0, type=PackedElementFieldNumericType.Uint8)
        ],
        data=bytes(row["grid"]),
    )


def stations(rows: Sequence[Row], stamp: float) -> SceneUpdate:
    """Charging stations as flat green discs of their charging radius."""
    entities = [
        SceneEntity(
            timestamp=timestamp(stamp),
            frame_id=WORLD_FRAME,
            id=str(r["station_id"]),
            cylinders=[
                CylinderPrimitive(
                    pose=pose(float(r["x"]), float(r["y"])),
                    size=Vector3(x=2 * r["radius_m"], y=2 * r["radius_m"], z=0.02),
                    bottom_scale=1.0,
                    top_scale=1.0,
                    color=Color(r=0.1, g=0.7, b=0.3, a=0.5),
                )
            ],
        )
        for r in rows
    ]
    return SceneUpdate(entities=entities)


def odometry_tf(row: Row) -> FrameTransforms:
    robot, stamp = str(row["robot_id"]), float(row["stamp"])
    return FrameTransforms(
        transforms=[
            FrameTransform(
                timestamp=timestamp(stamp),
                parent_frame_id=WORLD_FRAME,
                child_frame_id=base_link(robot),
                translation=Vector3(x=float(row["x"]), y=float(row["y"]), z=0.0),
                rotation=yaw_quaternion(float(row["yaw"])),
            )
        ]
    )


def odometry_pose(row: Row) -> PoseInFrame:
    return PoseInFrame(
        timestamp=timestamp(float(row["stamp"])),
        frame_id=WORLD_FRAME,
        pose=pose(float(row["x"]), float(row["y"]), float(row["yaw"])),
    )


def scan(row: Row) -> LaserScan:
    """A sweep in the robot's frame: beam i at ``angle_min + i * angle_increment``."""
    ranges = [float(r) for r in row["ranges"]]
    start = float(row["angle_min"])
    return LaserScan(
        timestamp=timestamp(float(row["stamp"])),
        frame_id=base_link(str(row["robot_id"])),
        pose=pose(0.0, 0.0),
        start_angle=start,
        end_angle=start + float(row["angle_increment"]) * max(0, len(ranges) - 1),
        ranges=ranges,
    )


def path(row: Row) -> PosesInFrame:
    """A ``planned_path`` row; no points: the planner has no path (an empty message)."""
    points = zip(row["xs"] or (), row["ys"] or (), strict=False)
    return PosesInFrame(
        timestamp=timestamp(float(row["stamp"])),
        frame_id=WORLD_FRAME,
        poses=[pose(float(x), float(y)) for x, y in points],
    )


def goal_pose(row: Row, stamp: float) -> PoseInFrame:
    return PoseInFrame(
        timestamp=timestamp(stamp),
        frame_id=WORLD_FRAME,
        pose=pose(float(row["x"]), float(row["y"])),
    )


def decision_log(row: Row) -> Log:
    """A ``command2robot`` row, one line: the command, the winner and why."""
    winner = row["source"] or "no recommendation"
    text = (
        f"#{row['id']} linear {row['linear_mps']:.3f} m/s, angular {row['angular_rps']:.3f} "
        f"rad/s from {winner} (recommendation {row['recommendation_id']}; considered "
        f"{list(row['considered_ids'] or [])}): {row['reason']}"
    )
    level = LogLevel.Info if row["recommendation_id"] is not None else LogLevel.Warning
    return event_log(float(row["stamp"]), text, "decision", level)


def event_log(stamp: float, text: str, name: str, level: LogLevel = LogLevel.Info) -> Log:
    return Log(timestamp=timestamp(stamp), level=level, message=text, name=name)


def json_ready(row: Row, columns: Sequence[str]) -> dict[str, Any]:
    """The columns of a row as JSON values (non-finite floats as null: JSON has none)."""
    out: dict[str, Any] = {}
    for column in columns:
        value = row[column]
        if isinstance(value, float) and not math.isfinite(value):
            value = None
        out[column] = value
    return out


RECOMMENDATION_COLUMNS = (
    "id", "robot_id", "kind", "source", "priority", "linear_mps", "angular_rps",
    "system_command", "stamp", "expires_stamp", "inputs", "reason",
)  # fmt: skip
BATTERY_COLUMNS = ("id", "robot_id", "stamp", "energy_wh", "capacity_wh", "percentage",
                   "charging", "power_w")  # fmt: skip


def _object(title: str, properties: dict[str, Any]) -> dict[str, Any]:
    return {"title": title, "type": "object", "properties": properties}


_NUM, _INT, _STR = {"type": ["number", "null"]}, {"type": "integer"}, {"type": ["string", "null"]}
RECOMMENDATION_SCHEMA = _object(
    "pnav.CommandRecommendation",
    {
        "id": _INT, "robot_id": _STR, "kind": _STR, "source": _STR, "priority": _INT,
        "linear_mps": _NUM, "angular_rps": _NUM, "system_command": _STR, "stamp": _NUM,
        "expires_stamp": _NUM, "inputs": {"type": "object"}, "reason": _STR,
    },
)  # fmt: skip
BATTERY_SCHEMA = _object(
    "pnav.Battery",
    {
        "id": _INT, "robot_id": _STR, "stamp": _NUM, "energy_wh": _NUM, "capacity_wh": _NUM,
        "percentage": _NUM, "charging": {"type": "boolean"}, "power_w": _NUM,
    },
)  # fmt: skip

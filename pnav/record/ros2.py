"""A recording in ROS 2 encoding (``--encoding ros2``): the robot's topics as rosbag2 writes
them, so ``ros2 bag play`` and Foxglove read the same file.

MCAP profile ``ros2``; each schema is ``ros2msg``, named ``pkg/msg/Name``, the type's message
definition followed by its dependencies, each after a line of 80 ``=`` and ``MSG: pkg/msg/Name``
(rosbag2's convention); each channel's messages are CDR (``common.ros2types``, Jazzy's types).
Topics as a ROS 2 robot would publish them under its namespace (the robot id), plus the world's
``/map`` and ``/tf``; the decisions, events, recommendations and goals have no ROS 2 message
and are left out (the default encoding records them).
"""

from __future__ import annotations

import functools
import math
import re
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from mcap.writer import CompressionType, Writer

from common import ros2types
from common.contract import keys
from pnav.record import topics
from pnav.record.recorder import Recorder
from pnav.ros2.rviz import path_msg
from services.sim.ros2wire import laser_scan

SEPARATOR = "=" * 80
UNKNOWN_CELL = 255  # the contract's unknown; OccupancyGrid's is -1

# topic (``{ns}``: the robot's namespace, its id) -> ROS 2 type: the table docs/RECORDING.md shows
TOPICS: dict[str, str] = {
    "/map": ros2types.OCCUPANCY_GRID,
    "/tf": ros2types.TF_MESSAGE,
    "/{ns}/scan": ros2types.LASER_SCAN,
    "/{ns}/odom": ros2types.ODOMETRY,
    "/{ns}/battery_state": ros2types.BATTERY_STATE,
    "/{ns}/plan": ros2types.PATH,
    "/{ns}/cmd_vel": ros2types.TWIST,
}


@functools.cache
def schema_text(name: str) -> str:
    """``name``'s ros2msg schema: its definition, then each dependency's after the separator."""
    text, _ = ros2types.store().generate_msgdef(name, ros_version=2)
    # rosbags names a dependency pkg/Name (ROS 1's form); rosbag2 writes pkg/msg/Name
    return re.sub(r"^MSG: ([^/\n]+)/([^/\n]+)$", r"MSG: \1/msg/\2", text, flags=re.MULTILINE)


class Ros2Writer:
    """An MCAP file of ROS 2 messages: a schema per type, a channel per topic."""

    def __init__(self, path: Path) -> None:
        self._stream: BinaryIO = path.open("xb")  # never overwrites
        self._writer = Writer(self._stream, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2", library="pnav.record")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}

    def write(self, topic: str, type_name: str, message: Any, stamp: float) -> None:
        channel = self._channels.get(topic)
        if channel is None:
            schema = self._schemas.get(type_name)
            if schema is None:
                data = schema_text(type_name).encode()
                schema = self._schemas[type_name] = self._writer.register_schema(
                    type_name, "ros2msg", data
                )
            channel = self._channels[topic] = self._writer.register_channel(topic, "cdr", schema)
        ns = topics.nanos(stamp)
        data = ros2types.encode(type_name, message)
        self._writer.add_message(channel, log_time=ns, data=data, publish_time=ns)

    def close(self) -> None:
        self._writer.finish()
        self._stream.close()


def frame(robot: str, name: str) -> str:
    return f"{robot}/{name}"


def _vector(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Any:
    return ros2types.message("geometry_msgs/msg/Vector3", x=x, y=y, z=z)


def _pose(x: float, y: float, yaw: float) -> Any:
    point = ros2types.message("geometry_msgs/msg/Point", x=x, y=y, z=0.0)
    return ros2types.message(
        "geometry_msgs/msg/Pose", position=point, orientation=ros2types.quaternion(yaw)
    )


def twist(linear: float, angular: float) -> Any:
    return ros2types.message(ros2types.TWIST, linear=_vector(x=linear), angular=_vector(z=angular))


def odometry(row: topics.Row) -> Any:
    """An ``odometry`` row: the pose in ``{ns}/odom`` (which ``/tf`` puts on ``map``)."""
    robot, stamp = str(row["robot_id"]), float(row["stamp"])
    zeros = np.zeros(36, dtype=np.float64)
    moving = twist(float(row["linear_mps"]), float(row["angular_rps"]))
    pose = _pose(float(row["x"]), float(row["y"]), float(row["yaw"]))
    return ros2types.message(
        ros2types.ODOMETRY,
        header=ros2types.header(stamp, frame(robot, "odom")),
        child_frame_id=frame(robot, "base_link"),
        pose=ros2types.message("geometry_msgs/msg/PoseWithCovariance", pose=pose, covariance=zeros),
        twist=ros2types.message(
            "geometry_msgs/msg/TwistWithCovariance", twist=moving, covariance=zeros
        ),
    )


def _transform(stamp: float, parent: str, child: str, x: float, y: float, yaw: float) -> Any:
    transform = ros2types.message(
        "geometry_msgs/msg/Transform",
        translation=_vector(x, y),
        rotation=ros2types.quaternion(yaw),
    )
    return ros2types.message(
        "geometry_msgs/msg/TransformStamped",
        header=ros2types.header(stamp, parent),
        child_frame_id=child,
        transform=transform,
    )


def tf(row: topics.Row) -> Any:
    """map -> ``{ns}/odom`` -> ``{ns}/base_link``: the recorder knows the pose in the map, so
    map -> odom is the identity and odom -> base_link the odometry's pose."""
    robot, stamp = str(row["robot_id"]), float(row["stamp"])
    odom, base = frame(robot, "odom"), frame(robot, "base_link")
    transforms = [
        _transform(stamp, topics.WORLD_FRAME, odom, 0.0, 0.0, 0.0),
        _transform(stamp, odom, base, float(row["x"]), float(row["y"]), float(row["yaw"])),
    ]
    return ros2types.message(ros2types.TF_MESSAGE, transforms=transforms)


def scan(row: topics.Row) -> Any:
    ranges = np.asarray([float(r) for r in row["ranges"]], dtype=np.float32)
    start, increment = float(row["angle_min"]), float(row["angle_increment"])
    return laser_scan(
        float(row["stamp"]),
        frame(str(row["robot_id"]), "base_link"),
        (start, start + increment * max(0, len(ranges) - 1), increment),
        (float(row["range_min"]), float(row["range_max"])),
        ranges,
    )


def battery(row: topics.Row) -> Any:
    def number(column: str) -> float:
        value = row[column]
        return math.nan if value is None else float(value)

    return ros2types.battery_state(
        float(row["stamp"]),
        frame(str(row["robot_id"]), "base_link"),
        power_w=number("power_w"),
        energy_wh=number("energy_wh"),
        capacity_wh=number("capacity_wh"),
        percentage=number("percentage"),
        charging=bool(row["charging"]),
    )


def occupancy_grid(row: topics.Row, stamp: float) -> Any:
    """The ``map`` row: the same layout (row 0 at the origin); unknown (255) becomes -1."""
    cells = np.frombuffer(bytes(row["grid"]), dtype=np.uint8).astype(np.int16)
    cells[cells == UNKNOWN_CELL] = -1
    origin = _pose(float(row["origin_x"]), float(row["origin_y"]), float(row["origin_yaw"]))
    info = ros2types.message(
        "nav_msgs/msg/MapMetaData",
        map_load_time=ros2types.time_msg(max(stamp, 0.0)),
        resolution=float(row["resolution_m"]),
        width=int(row["width"]),
        height=int(row["height"]),
        origin=origin,
    )
    return ros2types.message(
        ros2types.OCCUPANCY_GRID,
        header=ros2types.header(max(stamp, 0.0), topics.WORLD_FRAME),
        info=info,
        data=cells.astype(np.int8),
    )


class Ros2Recorder(Recorder):
    """The recorder's rows as the ROS 2 topics above; what has no ROS 2 message is skipped."""

    def _open(self) -> None:
        self.out = Ros2Writer(self.path)

    def write(self, topic: str, type_name: str, message: Any, stamp: float) -> None:
        self.out.write(topic, type_name, message, stamp)
        self.counts.messages += 1
        self.counts.per_topic[topic] = self.counts.per_topic.get(topic, 0) + 1

    def _record(self, table: str, row: dict[str, Any]) -> None:
        robot, stamp = str(row["robot_id"]), float(row["stamp"])
        if table == keys.ODOMETRY:
            self.write("/tf", ros2types.TF_MESSAGE, tf(row), stamp)
            self.write(f"/{robot}/odom", ros2types.ODOMETRY, odometry(row), stamp)
        elif table == keys.LASER_SCAN:
            self.write(f"/{robot}/scan", ros2types.LASER_SCAN, scan(row), stamp)
        elif table == keys.BATTERY:
            self.write(f"/{robot}/battery_state", ros2types.BATTERY_STATE, battery(row), stamp)
        elif table == keys.PLANNED_PATH:
            message = path_msg(stamp, list(row["xs"] or ()), list(row["ys"] or ()))
            self.write(f"/{robot}/plan", ros2types.PATH, message, stamp)
        elif table == keys.COMMAND2ROBOT:
            message = twist(float(row["linear_mps"]), float(row["angular_rps"]))
            self.write(f"/{robot}/cmd_vel", ros2types.TWIST, message, stamp)

    def _goal(self, row: dict[str, Any], stamp: float) -> None:
        pass  # no ROS 2 topic in this encoding

    def _changed(self, table: str, row: dict[str, Any]) -> None:
        pass  # events: no ROS 2 message

    async def _strategies(self) -> None:
        pass  # events: no ROS 2 message

    async def _world(self) -> None:
        row = await self._new_map()
        if row is None:
            return
        stamp = self._stamp(None)
        grid = occupancy_grid(dict(row.items()), stamp)
        self.write("/map", ros2types.OCCUPANCY_GRID, grid, stamp)

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self.out.close()

"""ROS 2 message types for the ROS 2 link: names, RIHS01 hashes, CDR (de)serialisation.

All from ``rosbags``, which ships the message definitions of every ROS 2 distribution and
computes the type hashes REP-2016 defines; no ROS installation is needed. The link speaks
Jazzy's types (its hashes are in every key expression; Humble has none and Kilted's of the
types used here are Jazzy's). Time stamps convert between a header's (sec, nanosec) and the
contract's float seconds here.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from common import ros2interfaces
from common.contract import rmw_zenoh

DISTRO: Final = Stores.ROS2_JAZZY

LASER_SCAN: Final = "sensor_msgs/msg/LaserScan"
ODOMETRY: Final = "nav_msgs/msg/Odometry"
BATTERY_STATE: Final = "sensor_msgs/msg/BatteryState"
TF_MESSAGE: Final = "tf2_msgs/msg/TFMessage"
TWIST: Final = "geometry_msgs/msg/Twist"
TWIST_STAMPED: Final = "geometry_msgs/msg/TwistStamped"
POSE_STAMPED: Final = "geometry_msgs/msg/PoseStamped"
PATH: Final = "nav_msgs/msg/Path"
OCCUPANCY_GRID: Final = "nav_msgs/msg/OccupancyGrid"
CLOCK: Final = "rosgraph_msgs/msg/Clock"

# sensor_msgs/BatteryState.power_supply_status
POWER_SUPPLY_STATUS_CHARGING: Final = 1
POWER_SUPPLY_STATUS_DISCHARGING: Final = 2
# The contract keeps a battery's energy (Wh) and power (W); ROS 2 its charge (Ah) and current
# (A): they are converted at a TurtleBot3's nominal 11.1 V (a 3-cell LiPo), which the message
# carries, so a reader gets the same Wh and W back.
NOMINAL_VOLTS: Final = 11.1


@functools.cache
def store() -> Typestore:
    """Jazzy's messages, and the services and actions the link serves (ros2interfaces)."""
    typestore = get_typestore(DISTRO)
    ros2interfaces.register(typestore, ros2interfaces.CANCEL_GOAL_TYPES)
    ros2interfaces.register(typestore, ros2interfaces.GET_STATE_TYPES)
    ros2interfaces.register(typestore, ros2interfaces.NAV2_TYPES)
    return typestore


@dataclass(frozen=True)
class RosType:
    name: str  # pkg/msg/Name
    hash: str  # RIHS01_<64 hex>

    @property
    def dds(self) -> str:
        return rmw_zenoh.dds_type(self.name)


@functools.cache
def ros_type(name: str) -> RosType:
    """The type named ``name`` (KeyError if the distribution has none of that name)."""
    if name not in store().types:
        raise KeyError(f"no ROS 2 type {name!r} in {DISTRO.value}")
    return RosType(name, ros2interfaces.rihs01(store(), name))


def message(name: str, **fields: Any) -> Any:
    """A message object of type ``name`` (fields left out are an error, as in rosbags)."""
    return store().types[name](**fields)


def encode(name: str, msg: Any) -> bytes:
    """A message as CDR (little-endian, with the 4-byte encapsulation header)."""
    return bytes(store().serialize_cdr(msg, name))


def decode(name: str, data: bytes) -> Any:
    """CDR bytes -> a message of type ``name``; any exception means the bytes are not one."""
    return store().deserialize_cdr(data, name)


def time_msg(seconds: float) -> Any:
    """``builtin_interfaces/msg/Time`` of ``seconds`` (>= 0)."""
    sec = math.floor(seconds)
    nanosec = min(round((seconds - sec) * 1e9), 999_999_999)
    return message("builtin_interfaces/msg/Time", sec=int(sec), nanosec=int(nanosec))


def duration_msg(seconds: float) -> Any:
    """``builtin_interfaces/msg/Duration`` of ``seconds``, clamped to [0, 2**31 - 1]."""
    seconds = min(max(seconds, 0.0), 2.0**31 - 1)
    sec = math.floor(seconds)
    nanosec = min(round((seconds - sec) * 1e9), 999_999_999)
    return message("builtin_interfaces/msg/Duration", sec=int(sec), nanosec=int(nanosec))


def pose_stamped(stamp: float, frame_id: str, x: float, y: float, yaw: float) -> Any:
    """A PoseStamped on the ground plane: (x, y), heading ``yaw``."""
    point = message("geometry_msgs/msg/Point", x=float(x), y=float(y), z=0.0)
    pose = message("geometry_msgs/msg/Pose", position=point, orientation=quaternion(yaw))
    return message(POSE_STAMPED, header=header(max(float(stamp), 0.0), frame_id), pose=pose)


def seconds_of(stamp: Any) -> float:
    return float(stamp.sec) + float(stamp.nanosec) * 1e-9


def header(seconds: float, frame_id: str) -> Any:
    return message("std_msgs/msg/Header", stamp=time_msg(seconds), frame_id=frame_id)


def yaw_of(q: Any) -> float:
    """The heading of a quaternion (rotation about z; roll and pitch ignored)."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def quaternion(yaw: float) -> Any:
    return message(
        "geometry_msgs/msg/Quaternion",
        x=0.0,
        y=0.0,
        z=math.sin(yaw / 2.0),
        w=math.cos(yaw / 2.0),
    )


def battery_state(
    stamp: float,
    frame_id: str,
    *,
    power_w: float,
    energy_wh: float,
    capacity_wh: float,
    percentage: float,
    charging: bool,
) -> Any:
    """A sensor_msgs/BatteryState from the contract's battery figures (percentage 0..100)."""
    volts = NOMINAL_VOLTS
    return message(
        BATTERY_STATE,
        header=header(stamp, frame_id),
        voltage=volts,
        temperature=math.nan,
        current=-power_w / volts,  # ROS: negative while discharging
        charge=energy_wh / volts,
        capacity=capacity_wh / volts,
        design_capacity=capacity_wh / volts,
        percentage=percentage / 100.0,
        power_supply_status=(
            POWER_SUPPLY_STATUS_CHARGING if charging else POWER_SUPPLY_STATUS_DISCHARGING
        ),
        power_supply_health=0,
        power_supply_technology=3,  # LiPo, as a TurtleBot3's
        present=True,
        cell_voltage=np.zeros(0, dtype=np.float32),
        cell_temperature=np.zeros(0, dtype=np.float32),
        location="",
        serial_number="",
    )


_DTYPES: Final = {
    "bool": np.bool_,
    "int8": np.int8,
    "uint8": np.uint8,
    "char": np.uint8,
    "byte": np.uint8,
    "int16": np.int16,
    "uint16": np.uint16,
    "int32": np.int32,
    "uint32": np.uint32,
    "int64": np.int64,
    "uint64": np.uint64,
    "float32": np.float32,
    "float64": np.float64,
}


def default(name: str) -> Any:
    """A message of type ``name`` with every field at its zero value (as a ROS 2 client
    library constructs one): numbers 0, strings empty, sequences empty, arrays of zeros."""
    return message(name, **{field: _zero(desc) for field, desc in store().fielddefs[name][1]})


def _zero(desc: Any) -> Any:
    kind, rest = desc
    if kind == Nodetype.NAME:
        return default(rest)
    if kind == Nodetype.BASE:
        base = rest[0]
        return "" if base == "string" else (False if base == "bool" else _DTYPES[base](0).item())
    inner, size = rest
    count = size if kind == Nodetype.ARRAY else 0
    if inner[0] == Nodetype.BASE and inner[1][0] in _DTYPES:
        return np.zeros(count, dtype=_DTYPES[inner[1][0]])
    return [_zero(inner) for _ in range(count)]

"""The sim's side of CONTRACT.md: the payloads it publishes and the cmd_vel it accepts.

Field names and types here are the contract; a change here is a contract change.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from common.robotmodel import LidarModel
from services.sim.battery import Battery
from services.sim.robot import RobotState


def scan(
    stamp: float, seq: int, params: LidarModel, ranges: npt.NDArray[np.float64]
) -> dict[str, Any]:
    """One sweep: ``ranges`` holds one range per beam of the model's lidar, beam i at
    ``angle_min + i * angle_increment`` from the heading (CONTRACT.md, the scan message)."""
    return {
        "stamp": stamp,
        "seq": seq,
        "angle_min": params.angle_min_rad,
        "angle_increment": params.angle_increment,
        "range_min": params.range_min_m,
        "range_max": params.range_max_m,
        # plain Python floats: msgpack cannot pack numpy scalars, and inf stays a float
        "ranges": ranges.tolist(),
    }


def odom(stamp: float, seq: int, robot: RobotState) -> dict[str, Any]:
    return {
        "stamp": stamp,
        "seq": seq,
        "x": robot.x,
        "y": robot.y,
        "yaw": robot.yaw,
        "linear": robot.linear,
        "angular": robot.angular,
    }


def battery(stamp: float, seq: int, bat: Battery) -> dict[str, Any]:
    return {
        "stamp": stamp,
        "seq": seq,
        "energy_wh": bat.energy_wh,
        "capacity_wh": bat.capacity_wh,
        "percentage": bat.percentage,
        "charging": bat.charging,
        "power_w": bat.power_w,
    }


def collision(stamp: float, seq: int, other: str, x: float, y: float) -> dict[str, Any]:
    return {"stamp": stamp, "seq": seq, "other": other, "x": x, "y": y}


def clock(stamp: float, rate: float) -> dict[str, Any]:
    return {"stamp": stamp, "rate": rate}


@dataclass(frozen=True)
class CmdVel:
    stamp: float
    linear: float
    angular: float
    command_id: int | None
    decided_stamp: float | None = None


def _finite(body: dict[str, Any], key: str) -> float:
    value = body.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"'{key}' must be a finite number, got {value!r}")
    return float(value)


def parse_cmd_vel(body: Any) -> CmdVel:
    """A cmd_vel payload (already msgpack-decoded); ValueError says what is wrong with it."""
    if not isinstance(body, dict):
        raise ValueError(f"cmd_vel must be a map, got {type(body).__name__}")
    command_id = body.get("command_id")
    if command_id is not None and (isinstance(command_id, bool) or not isinstance(command_id, int)):
        raise ValueError(f"'command_id' must be an int or nil, got {command_id!r}")
    decided = body.get("decided_stamp")
    return CmdVel(
        stamp=_finite(body, "stamp"),
        linear=_finite(body, "linear"),
        angular=_finite(body, "angular"),
        command_id=command_id,
        decided_stamp=None if decided is None else _finite(body, "decided_stamp"),
    )

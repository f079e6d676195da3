"""Validation of the sim's sensor payloads (CONTRACT.md, "Robot and sim") into typed records.

Everything that arrives on ``pnav/robot/{robot}/{scan,odom,battery,collision}`` comes from
outside the process and may be anything: random bytes, a map with the wrong types, a NaN
pose, a scan with 359 beams. Each parser either returns a record that is safe to insert as a
contract row, or raises :class:`MalformedMessage` whose ``reason`` is a short, fixed code
(the bridge counts malformed messages per topic and reason, so the codes must stay few).

Leniency, on purpose: an integer is accepted where the contract says float (some msgpack
writers pack ``0.0`` as ``0``); fields the contract does not name are ignored, so a newer
sim can add fields without breaking an older bridge. ``bool`` is never a number.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, field
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from common import bus
from common.contract import keys
from common.errors import ContractError

# A 360-beam scan packed as float64 is about 3.3 KB, a 720-beam one 6.5 KB; anything far
# larger is not a sensor message, and refusing it before decoding bounds the memory a bad
# publisher can cost us. 64 KB holds a scan of about 7000 beams.
MAX_PAYLOAD_BYTES: Final = 64 * 1024
# how many beams a scan may have is the robot model's (robot.lidar_beams): the bridge checks
# the scan's own shape, one sweep of at most a full turn
MAX_SCAN_BEAMS: Final = 100_000
# a full turn's last beam is one increment short of 2 pi; float error in a sender's
# increment is forgiven up to this
_SWEEP_TOLERANCE_RAD: Final = 1e-6

# Sanity bounds: generous for any indoor or outdoor robot, tight enough to catch garbage
# (a pose a light-year away is a bug, not a measurement).
MAX_ABS_POSITION_M: Final = 1.0e5
MAX_ABS_LINEAR_MPS: Final = 100.0
MAX_ABS_ANGULAR_RPS: Final = 1000.0
MAX_ABS_POWER_W: Final = 1.0e5
MAX_RANGE_M: Final = 1.0e4
MAX_TEXT: Final = 256
MAX_RUN: Final = 64  # a collision event's run id (migration 7's CHECK)
MAX_SEQ: Final = 2**63 - 1  # bigint
# percentage is energy/capacity x 100; float rounding may land a hair outside [0, 100]
PERCENT_SLACK: Final = 1e-6

# The reason codes, one per kind of fault.
TOO_LARGE: Final = "too_large"
BAD_MSGPACK: Final = "bad_msgpack"
NOT_A_MAP: Final = "not_a_map"
MISSING_FIELD: Final = "missing_field"
WRONG_TYPE: Final = "wrong_type"
NOT_FINITE: Final = "not_finite"
OUT_OF_RANGE: Final = "out_of_range"
BEAM_COUNT: Final = "beam_count"
BAD_RANGE: Final = "bad_range"
BAD_ROBOT_ID: Final = "bad_robot_id"
UNKNOWN_ROBOT: Final = "unknown_robot"
REASONS: Final = (
    TOO_LARGE,
    BAD_MSGPACK,
    NOT_A_MAP,
    MISSING_FIELD,
    WRONG_TYPE,
    NOT_FINITE,
    OUT_OF_RANGE,
    BEAM_COUNT,
    BAD_RANGE,
    BAD_ROBOT_ID,
    UNKNOWN_ROBOT,
)


class MalformedMessage(ContractError):
    """A payload that breaks CONTRACT.md; ``reason`` is one of :data:`REASONS`."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


@dataclass(frozen=True, slots=True)
class Odometry:
    robot_id: str
    stamp: float
    seq: int
    x: float
    y: float
    yaw: float
    linear: float
    angular: float


@dataclass(frozen=True, slots=True)
class LaserScan:
    robot_id: str
    stamp: float
    seq: int
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: list[float]
    # ``ranges`` as float64, when validation already made it (the safety layer's geometry
    # and the row image start from it; a record built by hand has None)
    array: npt.NDArray[np.float64] | None = field(default=None, compare=False, repr=False)

    def values(self) -> npt.NDArray[np.float64]:
        """``ranges`` as a float64 array: the one validation made, or one made now."""
        return self.array if self.array is not None else np.asarray(self.ranges, np.float64)


@dataclass(frozen=True, slots=True)
class BatteryState:
    robot_id: str
    stamp: float
    seq: int
    energy_wh: float
    capacity_wh: float
    percentage: float
    charging: bool
    power_w: float


@dataclass(frozen=True, slots=True)
class Collision:
    robot_id: str
    stamp: float
    seq: int
    other: str
    x: float
    y: float
    # the robot driver's run (CONTRACT.md): with seq, names the event across resends
    run: str | None = None


SensorRecord = Odometry | LaserScan | BatteryState | Collision


# -- field readers -----------------------------------------------------------------------
_MISSING: Final = object()


def _get(body: dict[str, Any], key: str) -> Any:
    value = body.get(key, _MISSING)
    if value is _MISSING:
        raise MalformedMessage(MISSING_FIELD, f"'{key}' is missing")
    return value


def number(body: dict[str, Any], key: str, lo: float = -math.inf, hi: float = math.inf) -> float:
    """A finite number within [lo, hi]."""
    value = _get(body, key)
    if isinstance(value, bool) or not isinstance(value, float | int):
        raise MalformedMessage(WRONG_TYPE, f"'{key}' must be a number, got {_kind(value)}")
    try:
        result = float(value)
    except OverflowError:  # a msgpack integer beyond float range
        raise MalformedMessage(NOT_FINITE, f"'{key}' is too large") from None
    if not math.isfinite(result):
        raise MalformedMessage(NOT_FINITE, f"'{key}' must be finite, got {result}")
    if not lo <= result <= hi:
        raise MalformedMessage(OUT_OF_RANGE, f"'{key}'={result} is outside [{lo}, {hi}]")
    return result


def integer(body: dict[str, Any], key: str, lo: int, hi: int) -> int:
    value = _get(body, key)
    if isinstance(value, bool) or not isinstance(value, int):
        raise MalformedMessage(WRONG_TYPE, f"'{key}' must be an integer, got {_kind(value)}")
    if not lo <= value <= hi:
        raise MalformedMessage(OUT_OF_RANGE, f"'{key}'={value} is outside [{lo}, {hi}]")
    return value


def boolean(body: dict[str, Any], key: str) -> bool:
    value = _get(body, key)
    if not isinstance(value, bool):
        raise MalformedMessage(WRONG_TYPE, f"'{key}' must be a bool, got {_kind(value)}")
    return value


def text(body: dict[str, Any], key: str, max_len: int = MAX_TEXT) -> str:
    value = _get(body, key)
    if not isinstance(value, str):
        raise MalformedMessage(WRONG_TYPE, f"'{key}' must be a string, got {_kind(value)}")
    if not 0 < len(value) <= max_len or "\x00" in value:  # Postgres text refuses NUL
        raise MalformedMessage(OUT_OF_RANGE, f"'{key}' must be 1 to {max_len} characters")
    return value


def _kind(value: Any) -> str:
    return "nil" if value is None else type(value).__name__


def wrap_angle(angle: float) -> float:
    """``angle`` in (-pi, pi], the contract's convention."""
    if -math.pi < angle <= math.pi:
        return angle
    wrapped = math.remainder(angle, math.tau)
    return math.pi if wrapped <= -math.pi else wrapped


# -- payloads ------------------------------------------------------------------------------
def decode(payload: bytes) -> dict[str, Any]:
    """msgpack bytes -> a map with string keys, or MalformedMessage."""
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise MalformedMessage(TOO_LARGE, f"{len(payload)} bytes > {MAX_PAYLOAD_BYTES}")
    try:
        body = bus.unpack(payload)
    except ValueError as exc:
        raise MalformedMessage(BAD_MSGPACK, str(exc)) from None
    if not isinstance(body, dict):
        raise MalformedMessage(NOT_A_MAP, f"the payload is a {_kind(body)}, not a map")
    return body


def _stamp_seq(body: dict[str, Any]) -> tuple[float, int]:
    return number(body, "stamp", 0.0), integer(body, "seq", 0, MAX_SEQ)


def _head(robot_id: str, body: dict[str, Any]) -> tuple[str, float, int]:
    """What a sensor record begins with: the robot, the stamp and the sequence number."""
    return (robot_id, *_stamp_seq(body))


def parse_odom(robot_id: str, body: dict[str, Any]) -> Odometry:
    p = MAX_ABS_POSITION_M
    return Odometry(
        *_head(robot_id, body),
        number(body, "x", -p, p),
        number(body, "y", -p, p),
        wrap_angle(number(body, "yaw", -1e6, 1e6)),
        number(body, "linear", -MAX_ABS_LINEAR_MPS, MAX_ABS_LINEAR_MPS),
        number(body, "angular", -MAX_ABS_ANGULAR_RPS, MAX_ABS_ANGULAR_RPS),
    )


def parse_scan(robot_id: str, body: dict[str, Any], beams: int | None = None) -> LaserScan:
    """A scan; ``beams``: how many its robot's lidar has (robot.lidar_beams), if known."""
    stamp, seq = _stamp_seq(body)
    angle_min = number(body, "angle_min", -math.tau, math.tau)
    # beams go counter-clockwise and one sweep covers at most a full turn
    increment = number(body, "angle_increment", 1e-9, math.tau)
    range_min = number(body, "range_min", 0.0, MAX_RANGE_M)
    range_max = number(body, "range_max", 0.0, MAX_RANGE_M)
    if not range_max > range_min:
        raise MalformedMessage(OUT_OF_RANGE, f"range_max {range_max} <= range_min {range_min}")
    ranges = _get(body, "ranges")
    if not isinstance(ranges, list):
        raise MalformedMessage(WRONG_TYPE, f"'ranges' must be an array, got {_kind(ranges)}")
    if not 1 <= len(ranges) <= MAX_SCAN_BEAMS:
        raise MalformedMessage(BEAM_COUNT, f"{len(ranges)} beams, not within [1, {MAX_SCAN_BEAMS}]")
    if beams is not None and len(ranges) != beams:
        raise MalformedMessage(BEAM_COUNT, f"{len(ranges)} beams, the robot's lidar has {beams}")
    if (len(ranges) - 1) * increment > math.tau + _SWEEP_TOLERANCE_RAD:
        raise MalformedMessage(
            BEAM_COUNT,
            f"{len(ranges)} beams {increment:g} rad apart sweep more than a full turn",
        )
    if set(map(type, ranges)) == {float}:
        # the sim's and any float64 writer's: every value checked at once
        array = np.array(ranges, dtype=np.float64)
        # refuses NaN (every comparison with it is false), -inf, negatives, and finite values
        # too large for real[]; +inf ("nothing in range") passes
        if (((array >= 0.0) & (array <= MAX_RANGE_M)) | (array == math.inf)).all():
            return LaserScan(
                robot_id, stamp, seq, angle_min, increment, range_min, range_max, ranges, array
            )
    values = _ranges(ranges)  # raises the first fault; ints become floats
    return LaserScan(robot_id, stamp, seq, angle_min, increment, range_min, range_max, values)


def _ranges(ranges: list[Any]) -> list[float]:
    """``ranges`` checked one by one: MalformedMessage naming the first bad value."""
    converted = False
    for i, value in enumerate(ranges):
        kind = type(value)
        if kind is not float:
            if kind is not int:  # also refuses bool, whose type is not int
                raise MalformedMessage(WRONG_TYPE, f"ranges[{i}] is a {_kind(value)}")
            converted = True
        if not 0 <= value <= MAX_RANGE_M and value != math.inf:
            raise MalformedMessage(BAD_RANGE, f"ranges[{i}]={value} (NaN, negative or huge)")
    return [float(v) for v in ranges] if converted else ranges


def parse_battery(robot_id: str, body: dict[str, Any]) -> BatteryState:
    stamp, seq = _stamp_seq(body)
    capacity = number(body, "capacity_wh", 0.0, 1e6)
    if capacity <= 0:
        raise MalformedMessage(OUT_OF_RANGE, "'capacity_wh' must be positive")
    energy = number(body, "energy_wh", 0.0, 1e6)
    percentage = number(body, "percentage", -PERCENT_SLACK, 100.0 + PERCENT_SLACK)
    return BatteryState(
        robot_id,
        stamp,
        seq,
        energy,
        capacity,
        min(max(percentage, 0.0), 100.0),
        boolean(body, "charging"),
        number(body, "power_w", -MAX_ABS_POWER_W, MAX_ABS_POWER_W),
    )


def parse_collision(robot_id: str, body: dict[str, Any]) -> Collision:
    p = MAX_ABS_POSITION_M
    return Collision(
        *_head(robot_id, body),
        text(body, "other"),
        number(body, "x", -p, p),
        number(body, "y", -p, p),
        None if body.get("run") is None else text(body, "run", MAX_RUN),
    )


Parser = Callable[[str, dict[str, Any]], SensorRecord]

PARSERS: Final[dict[str, Parser]] = {
    keys.SCAN: parse_scan,
    keys.ODOM: parse_odom,
    keys.BATTERY_MSG: parse_battery,
    keys.COLLISION: parse_collision,
}

# the contract table each sensor topic becomes
TABLE_OF_TOPIC: Final[dict[str, str]] = {
    keys.SCAN: keys.LASER_SCAN,
    keys.ODOM: keys.ODOMETRY,
    keys.BATTERY_MSG: keys.BATTERY,
    keys.COLLISION: keys.COLLISION_EVENT,
}


def robot_of(key: str, topic: str) -> str:
    """The robot id of a sensor key, or MalformedMessage if it is not a valid id."""
    try:
        robot_id, key_topic = keys.parse_robot_key(key)
    except ValueError:
        raise MalformedMessage(BAD_ROBOT_ID, f"not a robot key: {key!r}") from None
    if key_topic != topic or not keys.valid_id(robot_id):
        raise MalformedMessage(BAD_ROBOT_ID, f"bad robot id in {key!r}")
    return robot_id


def parse_sensor(
    topic: str, key: str, payload: bytes, known_robots: Collection[str] | Mapping[str, int]
) -> SensorRecord:
    """Validate one sample of ``topic`` received on ``key``; the robot must be known. Given
    as a mapping robot -> lidar beams (its robot row's ``lidar_beams``), a scan must have
    exactly that many ranges."""
    robot_id = robot_of(key, topic)
    if robot_id not in known_robots:
        raise MalformedMessage(UNKNOWN_ROBOT, f"robot {robot_id!r} is not in the robot table")
    if topic == keys.SCAN and isinstance(known_robots, Mapping):
        return parse_scan(robot_id, decode(payload), known_robots[robot_id])
    return PARSERS[topic](robot_id, decode(payload))

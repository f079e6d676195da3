"""Sensor and world payloads as the sim (or any foreign client) would send them, good and bad.

Shared by the bridge's unit tests (the parsers alone) and contract tests (over Zenoh).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import msgpack
from hypothesis import strategies as st

from common.contract import keys


def pack(body: Any) -> bytes:
    data: bytes = msgpack.packb(body, use_bin_type=True)
    return data


def odom(seq: int = 0, stamp: float = 1.0, **fields: Any) -> dict[str, Any]:
    body = {
        "stamp": stamp,
        "seq": seq,
        "x": 1.5,
        "y": -2.25,
        "yaw": 0.5,
        "linear": 0.2,
        "angular": -0.1,
    }
    return {**body, **fields}


def scan_ranges() -> list[float]:
    # a wall ahead, nothing in range behind: inf must survive the trip into real[]
    return [0.5 + 0.01 * i if i < 180 else math.inf for i in range(360)]


def scan(seq: int = 0, stamp: float = 1.0, **fields: Any) -> dict[str, Any]:
    body = {
        "stamp": stamp,
        "seq": seq,
        "angle_min": 0.0,
        "angle_increment": math.tau / 360,
        "range_min": 0.12,
        "range_max": 3.5,
        "ranges": scan_ranges(),
    }
    return {**body, **fields}


def battery(seq: int = 0, stamp: float = 1.0, **fields: Any) -> dict[str, Any]:
    body = {
        "stamp": stamp,
        "seq": seq,
        "energy_wh": 15.0,
        "capacity_wh": 19.98,
        "percentage": 15.0 / 19.98 * 100,
        "charging": True,
        "power_w": -5.0,
    }
    return {**body, **fields}


def collision(seq: int = 0, stamp: float = 1.0, **fields: Any) -> dict[str, Any]:
    body = {"stamp": stamp, "seq": seq, "other": "wall_3", "x": 0.75, "y": 1.25}
    return {**body, **fields}


VALID = {keys.SCAN: scan, keys.ODOM: odom, keys.BATTERY_MSG: battery, keys.COLLISION: collision}

NUMBER_FIELDS = {
    keys.ODOM: ("stamp", "x", "y", "yaw", "linear", "angular"),
    keys.SCAN: ("stamp", "angle_min", "angle_increment", "range_min", "range_max"),
    keys.BATTERY_MSG: ("stamp", "energy_wh", "capacity_wh", "percentage", "power_w"),
    keys.COLLISION: ("stamp", "x", "y"),
}
# field -> values that are the wrong type for it (numbers are right for number fields)
_junk = st.one_of(
    st.text(max_size=4),
    st.none(),
    st.binary(max_size=4),
    st.lists(st.integers(0, 9), max_size=3),
    st.dictionaries(st.text(max_size=3), st.integers(0, 9), max_size=2),
)
WRONG_TYPES: dict[str, st.SearchStrategy[Any]] = {
    "number": st.one_of(_junk, st.booleans()),
    "seq": st.one_of(_junk, st.booleans(), st.floats(allow_nan=False)),
    "charging": st.one_of(
        st.text(max_size=4), st.none(), st.integers(0, 1), st.floats(allow_nan=False)
    ),
    "other": st.one_of(
        st.none(), st.booleans(), st.integers(-(2**63), 2**63 - 1), st.binary(max_size=4)
    ),
    "ranges": st.one_of(
        st.text(max_size=4), st.none(), st.integers(-(2**63), 2**63 - 1), st.binary(max_size=4)
    ),
}


def _kind_of(topic: str, field: str) -> str:
    if field in NUMBER_FIELDS[topic]:
        return "number"
    return field


@dataclass(frozen=True)
class Bad:
    """One malformed sample: where it goes, its bytes, and the reason the bridge should give
    (None when any reason will do, e.g. for random bytes)."""

    topic: str
    robot: str
    payload: bytes
    reason: str | None

    @property
    def key(self) -> str:
        return keys.robot_key(self.robot, self.topic)


topics = st.sampled_from(keys.SENSOR_TOPICS)


@st.composite
def random_bytes(draw: st.DrawFn, robot: str) -> Bad:
    return Bad(draw(topics), robot, draw(st.binary(max_size=64)), None)


@st.composite
def not_msgpack(draw: st.DrawFn, robot: str) -> Bad:
    # 0xc1 is the one byte msgpack never uses
    return Bad(draw(topics), robot, b"\xc1" + draw(st.binary(max_size=16)), "bad_msgpack")


@st.composite
def not_a_map(draw: st.DrawFn, robot: str) -> Bad:
    body = draw(
        st.one_of(
            st.integers(-(2**63), 2**63 - 1), st.text(max_size=8), st.lists(st.floats(), max_size=4)
        )
    )
    return Bad(draw(topics), robot, pack(body), "not_a_map")


@st.composite
def wrong_type(draw: st.DrawFn, robot: str) -> Bad:
    topic = draw(topics)
    body = VALID[topic]()
    field = draw(st.sampled_from(sorted(body)))
    body[field] = draw(WRONG_TYPES[_kind_of(topic, field)])
    return Bad(topic, robot, pack(body), "wrong_type")


@st.composite
def not_finite(draw: st.DrawFn, robot: str) -> Bad:
    topic = draw(topics)
    body = VALID[topic]()
    body[draw(st.sampled_from(NUMBER_FIELDS[topic]))] = draw(
        st.sampled_from([math.nan, math.inf, -math.inf])
    )
    return Bad(topic, robot, pack(body), "not_finite")


@st.composite
def missing_field(draw: st.DrawFn, robot: str) -> Bad:
    topic = draw(topics)
    body = VALID[topic]()
    del body[draw(st.sampled_from(sorted(body)))]
    return Bad(topic, robot, pack(body), "missing_field")


@st.composite
def beam_count(draw: st.DrawFn, robot: str) -> Bad:
    n = draw(st.integers(0, 720).filter(lambda n: n != 360))
    return Bad(keys.SCAN, robot, pack(scan(ranges=[1.0] * n)), "beam_count")


@st.composite
def bad_range(draw: st.DrawFn, robot: str) -> Bad:
    ranges = scan_ranges()
    value = draw(
        st.one_of(
            st.just(math.nan),
            st.just(-math.inf),
            st.floats(max_value=-1e-9),
            st.floats(min_value=1e4 + 1, allow_infinity=False),  # beyond real[] or any lidar
        )
    )
    ranges[draw(st.integers(0, 359))] = value
    return Bad(keys.SCAN, robot, pack(scan(ranges=ranges)), "bad_range")


@st.composite
def out_of_range(draw: st.DrawFn, robot: str) -> Bad:
    choice = draw(st.integers(0, 3))
    if choice == 0:
        body, topic = battery(percentage=draw(st.floats(100.01, 1e6))), keys.BATTERY_MSG
    elif choice == 1:
        body, topic = battery(energy_wh=draw(st.floats(-1e6, -0.01))), keys.BATTERY_MSG
    elif choice == 2:
        body, topic = odom(x=draw(st.floats(1e6, 1e300))), keys.ODOM
    else:
        body, topic = scan(range_max=0.05), keys.SCAN  # below range_min
    return Bad(topic, robot, pack(body), "out_of_range")


@st.composite
def unknown_robot(draw: st.DrawFn, robot: str) -> Bad:
    topic = draw(topics)
    return Bad(topic, "ghost", pack(VALID[topic]()), "unknown_robot")


@st.composite
def bad_robot_id(draw: st.DrawFn, robot: str) -> Bad:
    topic = draw(topics)
    name = draw(st.sampled_from(["r.1", "r+1", "r~1", "r%1"]))
    return Bad(topic, name, pack(VALID[topic]()), "bad_robot_id")


def bad_messages(robot: str = "r1") -> st.SearchStrategy[Bad]:
    """Every kind of malformed sensor sample, for a known ``robot``."""
    return st.one_of(
        random_bytes(robot),
        not_msgpack(robot),
        not_a_map(robot),
        wrong_type(robot),
        not_finite(robot),
        missing_field(robot),
        beam_count(robot),
        bad_range(robot),
        out_of_range(robot),
        unknown_robot(robot),
        bad_robot_id(robot),
    )


def world(
    name: str = "test_world",
    robots: tuple[str, ...] = ("r1",),
    stations: tuple[tuple[str, float, float], ...] = (("c1", 2.0, 3.0),),
    **robot_fields: Any,
) -> dict[str, Any]:
    """A ``pnav/sim/world`` message: a 4 x 3 map with one occupied and one unknown cell."""
    grid = bytes([0, 0, 100, 0, 0, 255, 0, 0, 0, 0, 0, 0])
    limits = {
        "model": "turtlebot3_burger",
        "wheel_radius_m": 0.033,
        "wheel_separation_m": 0.160,
        "max_linear_mps": 0.22,
        "max_angular_rps": 2.84,
        "footprint_radius_m": 0.105,
        "battery_capacity_wh": 19.98,
        **robot_fields,
    }
    return {
        "name": name,
        "map": {
            "resolution": 0.5,
            "origin": [-1.0, -0.5, 0.0],
            "width": 4,
            "height": 3,
            "grid": grid,
            "source": "worlds/test.yaml",
        },
        "robots": [
            {"robot_id": r, "x": float(i), "y": 0.0, "yaw": 0.0, **limits}
            for i, r in enumerate(robots)
        ],
        "charging_stations": [
            {"station_id": s, "x": x, "y": y, "radius_m": 0.3, "charge_power_w": 10.0}
            for s, x, y in stations
        ],
    }

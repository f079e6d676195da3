"""The bridge's sensor validation: good payloads become exact records, bad ones a reason."""

from __future__ import annotations

import math
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from common.contract import keys
from common.errors import ContractError
from services.bridge import sensor_payloads as messages
from services.bridge.sensor_payloads import (
    BatteryState,
    Collision,
    LaserScan,
    MalformedMessage,
    Odometry,
    parse_sensor,
)
from tests.unit.bridge import payloads
from tests.unit.bridge.payloads import Bad, bad_messages, pack

KNOWN = {"r1": 360}  # the robot table: r1, whose lidar has 360 beams
finite = st.floats(-1e3, 1e3, allow_nan=False)


def parse(topic: str, body: Any, robot: str = "r1") -> messages.SensorRecord:
    return parse_sensor(topic, keys.robot_key(robot, topic), pack(body), KNOWN)


def test_each_valid_payload_becomes_its_record() -> None:
    assert parse(keys.ODOM, payloads.odom(seq=7, stamp=2.5)) == Odometry(
        "r1", 2.5, 7, 1.5, -2.25, 0.5, 0.2, -0.1
    )
    assert parse(keys.BATTERY_MSG, payloads.battery(seq=1)) == BatteryState(
        "r1", 1.0, 1, 15.0, 19.98, 15.0 / 19.98 * 100, True, -5.0
    )
    assert parse(keys.COLLISION, payloads.collision(seq=2, other="r2")) == Collision(
        "r1", 1.0, 2, "r2", 0.75, 1.25
    )
    record = parse(keys.SCAN, payloads.scan(seq=3))
    assert isinstance(record, LaserScan)
    assert (record.seq, record.range_min, record.range_max) == (3, 0.12, 3.5)
    assert record.ranges[0] == 0.5 and record.ranges[359] == math.inf
    assert len(record.ranges) == 360


def test_integers_are_accepted_where_the_contract_says_float() -> None:
    record = parse(keys.ODOM, payloads.odom(stamp=3, x=1, y=0, yaw=0, linear=0, angular=0))
    assert isinstance(record, Odometry) and record.stamp == 3.0 and isinstance(record.x, float)
    scan = parse(keys.SCAN, payloads.scan(ranges=[1] * 360))
    assert isinstance(scan, LaserScan) and all(type(r) is float for r in scan.ranges)


def test_fields_the_contract_does_not_name_are_ignored() -> None:
    assert isinstance(parse(keys.ODOM, payloads.odom(covariance=[0.1] * 36)), Odometry)


def test_yaw_is_wrapped_into_the_contract_interval() -> None:
    for yaw, expected in ((math.pi, math.pi), (-math.pi, math.pi), (3 * math.pi / 2, -math.pi / 2)):
        record = parse(keys.ODOM, payloads.odom(yaw=yaw))
        assert isinstance(record, Odometry)
        assert record.yaw == pytest.approx(expected)


def test_a_percentage_a_rounding_error_above_100_is_clamped() -> None:
    record = parse(keys.BATTERY_MSG, payloads.battery(percentage=100.0 + 1e-9))
    assert isinstance(record, BatteryState) and record.percentage == 100.0


@settings(max_examples=300, deadline=None)
@given(bad_messages())
def test_every_malformed_payload_is_refused_with_its_reason(bad: Bad) -> None:
    with pytest.raises(MalformedMessage) as caught:
        parse_sensor(bad.topic, bad.key, bad.payload, KNOWN)
    assert caught.value.reason in messages.REASONS
    assert isinstance(caught.value, ContractError)
    if bad.reason is not None:
        assert caught.value.reason == bad.reason, caught.value


_msgpack_values = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**63), 2**64 - 1) | st.floats() | st.text(),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner),
    max_leaves=20,
)


@settings(max_examples=300, deadline=None)
@given(topic=st.sampled_from(keys.SENSOR_TOPICS), body=_msgpack_values)
def test_arbitrary_structures_never_raise_anything_but_malformed(topic: str, body: Any) -> None:
    try:
        parse(topic, body)
    except MalformedMessage:
        pass


@settings(max_examples=200, deadline=None)
@given(
    seq=st.integers(0, 2**63 - 1),
    stamp=st.floats(0, 1e9),
    pose=st.tuples(finite, finite, st.floats(-math.pi, math.pi).filter(lambda a: a > -math.pi)),
    twist=st.tuples(st.floats(-100, 100), st.floats(-1000, 1000)),
)
def test_valid_odometry_round_trips(
    seq: int, stamp: float, pose: tuple[float, float, float], twist: tuple[float, float]
) -> None:
    x, y, yaw = pose
    body = payloads.odom(seq, stamp, x=x, y=y, yaw=yaw, linear=twist[0], angular=twist[1])
    assert parse(keys.ODOM, body) == Odometry("r1", stamp, seq, x, y, yaw, *twist)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(0, 3.5) | st.just(math.inf), min_size=360, max_size=360))
def test_valid_scans_keep_every_range(ranges: list[float]) -> None:
    record = parse(keys.SCAN, payloads.scan(ranges=ranges))
    assert isinstance(record, LaserScan) and record.ranges == ranges


def test_oversized_payloads_are_refused_before_decoding() -> None:
    with pytest.raises(MalformedMessage) as caught:
        parse(keys.SCAN, payloads.scan(padding="x" * messages.MAX_PAYLOAD_BYTES))
    assert caught.value.reason == messages.TOO_LARGE


def test_a_key_of_another_topic_is_refused() -> None:
    with pytest.raises(MalformedMessage) as caught:
        parse_sensor(keys.ODOM, keys.robot_key("r1", keys.SCAN), pack(payloads.odom()), KNOWN)
    assert caught.value.reason == messages.BAD_ROBOT_ID


@pytest.mark.parametrize(
    ("value", "reason", "detail"),
    [
        (math.nan, "bad_range", "ranges[7]=nan"),
        (-0.5, "bad_range", "ranges[7]=-0.5"),
        (-math.inf, "bad_range", "ranges[7]=-inf"),
        (2e4, "bad_range", "ranges[7]=20000.0"),
        (True, "wrong_type", "ranges[7] is a bool"),
        (None, "wrong_type", "ranges[7] is a nil"),
        ("1.0", "wrong_type", "ranges[7] is a str"),
    ],
)
def test_a_bad_beam_among_floats_is_named_by_its_index(
    value: Any, reason: str, detail: str
) -> None:
    # the later bad beam must not be the one reported: every float is checked at once first
    ranges: list[Any] = payloads.scan_ranges()
    ranges[7], ranges[300] = value, -1.0
    with pytest.raises(MalformedMessage) as caught:
        parse(keys.SCAN, payloads.scan(ranges=ranges))
    assert caught.value.reason == reason
    assert caught.value.detail.split(" (")[0] == detail


def test_a_scan_of_floats_carries_its_ranges_as_an_array_too() -> None:
    floats = parse(keys.SCAN, payloads.scan())
    assert isinstance(floats, LaserScan) and floats.array is not None
    assert floats.array.tolist() == floats.ranges == payloads.scan_ranges()
    # a lenient writer's integers take the one-by-one way: floats, and no array
    mixed = parse(keys.SCAN, payloads.scan(ranges=[1, *payloads.scan_ranges()[1:]]))
    assert isinstance(mixed, LaserScan) and mixed.array is None
    assert type(mixed.ranges[0]) is float
    assert mixed.ranges == [1.0, *payloads.scan_ranges()[1:]]

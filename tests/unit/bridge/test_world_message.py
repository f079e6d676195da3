"""Parsing the sim's world message into the rows the bridge will upsert."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from common.robotmodel import load_model
from services.bridge.sensor_payloads import MalformedMessage
from services.bridge.world_message import ROBOT_DEFAULTS, MapInfo, StationInfo, parse_world
from tests.unit.bridge import payloads
from tests.unit.bridge.payloads import pack


def test_a_world_message_parses_into_map_robots_and_stations() -> None:
    world = parse_world(pack(payloads.world(robots=("r1", "r2"), max_linear_mps=0.5)))
    assert world.name == "test_world"
    assert world.map == MapInfo(
        "test_world",
        0.5,
        -1.0,
        -0.5,
        0.0,
        4,
        3,
        payloads.world()["map"]["grid"],
        "worlds/test.yaml",
    )
    assert [r.robot_id for r in world.robots] == ["r1", "r2"]
    assert world.robots[0].max_linear_mps == 0.5
    assert world.robots[0].max_angular_rps == 2.84
    assert world.stations == (StationInfo("c1", 2.0, 3.0, 0.3, 10.0),)


def test_limits_left_out_take_the_contract_defaults() -> None:
    body = payloads.world()
    body["robots"] = [{"robot_id": "r1"}]
    robot = parse_world(pack(body)).robots[0]
    assert robot.model == "turtlebot3_burger"
    assert robot.max_linear_mps == ROBOT_DEFAULTS["max_linear_mps"]


def _broken(change: str) -> dict[str, Any]:
    body = payloads.world(robots=("r1", "r2"))
    if change == "grid size":
        body["map"]["grid"] = b"\x00" * 5
    elif change == "grid type":
        body["map"]["grid"] = list(body["map"]["grid"])
    elif change == "robot id":
        body["robots"][0]["robot_id"] = "r/1"
    elif change == "duplicate robot":
        body["robots"][1]["robot_id"] = "r1"
    elif change == "negative limit":
        body["robots"][0]["max_linear_mps"] = -0.2
    elif change == "nan origin":
        body["map"]["origin"] = [float("nan"), 0.0, 0.0]
    elif change == "no stations":
        del body["charging_stations"]
    elif change == "station radius":
        body["charging_stations"][0]["radius_m"] = 0.0
    elif change == "map not a map":
        body["map"] = [1, 2]
    return body


@pytest.mark.parametrize(
    "change",
    [
        "grid size",
        "grid type",
        "robot id",
        "duplicate robot",
        "negative limit",
        "nan origin",
        "no stations",
        "station radius",
        "map not a map",
    ],
)
def test_a_broken_world_is_refused(change: str) -> None:
    with pytest.raises(MalformedMessage):
        parse_world(pack(_broken(change)))


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=200))
def test_random_bytes_are_never_a_world(data: bytes) -> None:
    with pytest.raises(MalformedMessage):
        parse_world(data)


def test_every_model_column_of_a_jackal_comes_through() -> None:
    jackal = load_model("jackal").robot_row()
    body = payloads.world()
    body["robots"] = [{"robot_id": "j1", **jackal}]
    robot = parse_world(pack(body)).robots[0]
    assert robot.columns() == {"robot_id": "j1", **jackal}


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("lidar_beams", 0),
        ("lidar_beams", 360.0),
        ("lidar_fov_rad", 7.0),
        ("lidar_fov_rad", 0.0),
        ("lidar_range_max_m", 0.05),  # not above range_min
        ("lidar_noise_m", -0.01),
        ("lidar_rate_hz", 0.0),
        ("max_linear_accel_mps2", 0.0),
        ("max_angular_accel_rps2", 1000.0),
        ("lidar_angle_min_rad", 10.0),
    ],
)
def test_a_model_column_the_contract_refuses_is_refused_before_sql(
    field: str, value: float
) -> None:
    body = payloads.world()
    body["robots"][0][field] = value
    with pytest.raises(MalformedMessage):
        parse_world(pack(body))


@pytest.mark.parametrize(
    ("polygon", "says"),
    [
        ([[0.2, 0.2], [-0.2, -0.2], [0.2, -0.2], [-0.2, 0.2]], "self-intersecting"),
        ([[1.0, -0.2], [1.5, -0.2], [1.5, 0.2], [1.0, 0.2]], "centre"),
        ([[0.2, -0.2], [float("nan"), 0.2], [-0.2, 0.0]], "finite"),
        ("box", "list of [x, y]"),
    ],
)
def test_a_footprint_polygon_the_table_would_refuse_is_refused_naming_it(
    polygon: object, says: str
) -> None:
    body = payloads.world()
    body["robots"][0]["footprint_polygon"] = polygon
    with pytest.raises(MalformedMessage) as caught:
        parse_world(pack(body))
    assert "footprint_polygon" in str(caught.value) and says in str(caught.value)


def test_a_robot_without_a_polygon_is_its_disc() -> None:
    body = payloads.world()
    body["robots"][0].pop("footprint_polygon", None)
    assert parse_world(pack(body)).robots[0].footprint_polygon is None

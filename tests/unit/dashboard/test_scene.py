"""The page's drawing data, from rows: lidar hits in the world frame, the map, decisions."""

from __future__ import annotations

import base64
import math

import pytest

from services.dashboard import scene

POSE = {"x": 2.0, "y": 1.0, "yaw": math.pi}


def scan(ranges: list[float], angle_min: float = 0.0) -> dict[str, object]:
    return {
        "angle_min": angle_min,
        "angle_increment": math.pi / 2,
        "range_min": 0.12,
        "range_max": 3.5,
        "ranges": ranges,
    }


def test_each_hit_is_placed_from_the_pose_along_its_beam() -> None:
    # facing -x: beam 0 ahead (-x), beam 1 a quarter turn left (-y), beam 2 behind (+x)
    points = scene.lidar_points(scan([1.0, 0.5, 2.0, 1.0]), POSE)
    assert points == [1.0, 1.0, 2.0, 0.5, 4.0, 1.0, 2.0, 2.0]


def test_angle_min_turns_every_beam() -> None:
    # beam 0 a quarter turn left of the heading (-x): -y
    assert scene.lidar_points(scan([1.0], angle_min=math.pi / 2), POSE) == [2.0, 0.0]


@pytest.mark.parametrize("reading", [math.inf, math.nan, 0.05, 3.5, 7.0])
def test_no_return_and_readings_outside_the_range_are_not_hits(reading: float) -> None:
    assert scene.lidar_points(scan([reading, 1.0]), POSE) == [2.0, 0.0]


def test_the_map_is_sent_as_its_geometry_and_base64_cells() -> None:
    row = {
        "map_id": "room",
        "resolution_m": 0.05,
        "origin_x": -1.0,
        "origin_y": -2.0,
        "origin_yaw": 0.0,
        "width": 2,
        "height": 1,
        "grid": b"\x00\x64",
    }
    sent = scene.world_map(row)
    assert sent is not None
    assert sent["origin"] == [-1.0, -2.0, 0.0] and sent["width"] == 2
    assert base64.b64decode(sent["grid"]) == b"\x00\x64"
    assert scene.world_map(None) is None


def rec(rec_id: int, priority: int, source: str) -> dict[str, object]:
    return {
        "id": rec_id,
        "kind": "robot",
        "source": source,
        "priority": priority,
        "linear_mps": 0.1,
        "angular_rps": math.nan,  # never sent as NaN: JSON has none
        "stamp": 1.0,
        "expires_stamp": 1.5,
        "reason": "r",
        "inputs": {"laser_scan": 3, "scan_stamp": math.inf},
    }


def test_a_decision_lists_what_it_weighed_highest_priority_then_newest_first() -> None:
    row = {
        "id": 9,
        "stamp": 1.0,
        "linear_mps": 0.0,
        "angular_rps": 0.4,
        "source": "safety_stop",
        "reason": "why",
        "recommendation_id": 3,
        "considered_ids": [1, 2, 3],
    }
    weighed = [rec(1, 10, "turn_then_move"), rec(2, 50, "avoid_left"), rec(3, 100, "stop")]
    decision = scene.decision(row, weighed)
    assert [r["id"] for r in decision["considered"]] == [3, 2, 1]
    assert decision["considered"][0]["angular"] is None
    assert decision["considered"][0]["inputs"] == {"laser_scan": 3, "scan_stamp": None}
    assert decision["safety"] is None

"""Which notifications a written batch gives, and their images (the writer's pure part)."""

from __future__ import annotations

import math
from array import array

import numpy as np

from common.contract import keys
from services.bridge.sensor_payloads import LaserScan, Odometry
from services.bridge.sensor_tables import SENSOR_TABLES, newest_per_robot

ODOMETRY = SENSOR_TABLES[Odometry]
LASER_SCAN = SENSOR_TABLES[LaserScan]


def odom(robot: str, seq: int) -> Odometry:
    return Odometry(robot, seq / 30, seq, 1.0, 2.0, 0.5, 0.2, -0.1)


def test_one_notification_per_robot_with_the_newest_row_and_its_image() -> None:
    batch = [odom("r1", 0), odom("r2", 0), odom("r1", 1), odom("r2", 1), odom("r1", 2)]
    returned = [(10, "r1"), (11, "r2"), (12, "r1"), (13, "r2"), (14, "r1")]
    notes = newest_per_robot(ODOMETRY, batch, returned, images=True)
    assert [(robot, row_id) for robot, row_id, _ in notes] == [("r1", 14), ("r2", 13)]
    image = notes[0][2]
    assert image == {
        "id": 14,
        "robot_id": "r1",
        "stamp": 2 / 30,
        "seq": 2,
        "x": 1.0,
        "y": 2.0,
        "yaw": 0.5,
        "linear_mps": 0.2,
        "angular_rps": -0.1,
    }
    assert notes[1][2] is not None and notes[1][2]["seq"] == 1  # r2's newest: its record


def test_no_image_when_images_are_off_or_the_ids_cannot_be_paired_with_the_records() -> None:
    batch = [odom("r1", 0), odom("r2", 0)]
    assert newest_per_robot(ODOMETRY, batch, [(1, "r1"), (2, "r2")], images=False) == [
        ("r1", 1, None),
        ("r2", 2, None),
    ]
    # RETURNING in another order than the records went in: the ids still notify, bare
    swapped = newest_per_robot(ODOMETRY, batch, [(2, "r2"), (1, "r1")], images=True)
    assert swapped == [("r2", 2, None), ("r1", 1, None)]
    short = newest_per_robot(ODOMETRY, batch, [(1, "r1")], images=True)
    assert short == [("r1", 1, None)]


def test_a_scan_image_holds_its_ranges_as_real_keeps_them() -> None:
    ranges = [0.1 * i for i in range(359)] + [math.inf]
    scan = LaserScan("r1", 1.0, 3, 0.0, math.tau / 360, 0.12, 3.5, ranges)
    [(_, _, image)] = newest_per_robot(LASER_SCAN, [scan], [(5, "r1")], images=True)
    assert image is not None
    assert image["ranges"] == list(array("f", ranges))  # float32 values, as floats
    assert image["ranges"] != ranges and image["ranges"][-1] == math.inf
    assert set(image) == {
        "id",
        "robot_id",
        "stamp",
        "seq",
        "angle_min",
        "angle_increment",
        "range_min",
        "range_max",
        "ranges",
    }
    assert LASER_SCAN.name == keys.LASER_SCAN


def test_a_scan_image_is_the_same_from_a_validated_scan_as_from_its_list() -> None:
    ranges = [0.1 * i + 1e-9 for i in range(359)] + [math.inf]
    by_hand = LaserScan("r1", 1.0, 3, 0.0, math.tau / 360, 0.12, 3.5, ranges)
    validated = LaserScan(
        "r1", 1.0, 3, 0.0, math.tau / 360, 0.12, 3.5, ranges, np.array(ranges, dtype=np.float64)
    )
    [(_, _, one)] = newest_per_robot(LASER_SCAN, [by_hand], [(5, "r1")], images=True)
    [(_, _, other)] = newest_per_robot(LASER_SCAN, [validated], [(5, "r1")], images=True)
    assert one is not None and other is not None
    assert other["ranges"] == one["ranges"] == list(array("f", ranges))
    assert all(type(r) is float for r in other["ranges"])  # msgpack packs them as floats

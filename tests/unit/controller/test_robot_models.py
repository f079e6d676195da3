"""The controller scenarios read the robot row: footprint, limits and acceleration size their
distances, and a lidar with a partial field of view is not taken for a clear one."""

from __future__ import annotations

import math

import numpy as np

from common.contract.records import LaserScan, Robot
from common.robotmodel import load_model
from services.controller.avoid import AvoidParams, decide_turn
from services.controller.safety_stop import SafetyStop
from services.controller.sectors import ScanView, deg
from tests.unit.controller.scans import BURGER, odom

_J = load_model("jackal")
JACKAL = Robot(
    "r1",
    max_linear_mps=_J.max_linear_mps,
    max_angular_rps=_J.max_angular_rps,
    footprint_radius_m=_J.footprint_radius_m,
    battery_capacity_wh=_J.battery_capacity_wh,
    max_linear_accel_mps2=_J.max_linear_accel_mps2,
    max_angular_accel_rps2=_J.max_angular_accel_rps2,
)


def jackal_scan(*obstacles: tuple[float, float, float]) -> LaserScan:
    """The Jackal's sweep: 720 beams from -135 to +135 deg, inf except the obstacles
    ``(from deg, to deg, range m)``."""
    angles = np.linspace(-135.0, 135.0, 720)
    ranges = np.full(720, np.inf)
    for low, high, distance in obstacles:
        mask = (angles >= low) & (angles <= high)
        ranges[mask] = np.minimum(ranges[mask], distance)
    return LaserScan(
        id=1,
        robot_id="r1",
        stamp=10.0,
        angle_min=math.radians(-135.0),
        angle_increment=math.radians(270.0) / 719,
        range_min=0.1,
        range_max=30.0,
        ranges=ranges.astype(np.float32),
    )


def test_a_sector_outside_the_field_of_view_is_unseen_not_open() -> None:
    view = ScanView(jackal_scan())
    assert view.sees((-deg(30), deg(30)))
    assert not view.sees((deg(150), deg(210)))  # straight behind: no beams
    assert view.openness((deg(150), deg(210)), 2.0) == 0.0
    assert view.openness((-deg(30), deg(30)), 2.0) == 2.0


def test_a_seen_side_is_freer_than_an_unseen_one_even_with_an_obstacle() -> None:
    view = ScanView(jackal_scan((100.0, 135.0, 0.5)))
    # the back-left (90..180) is half seen, with an obstacle; the back-right beyond -135 deg
    # unseen: only (150, 180) vs (-180, -150) makes one side wholly unseen
    assert view.left_is_freer((deg(100), deg(130)), (-deg(180), -deg(150)), 1.0)
    assert not view.left_is_freer((deg(150), deg(180)), (-deg(130), -deg(100)), 1.0)


def test_backing_up_blind_stops_and_says_why() -> None:
    command = SafetyStop.decide(jackal_scan(), odom(-0.3), JACKAL, {})
    assert command is not None and (command.linear, command.angular) == (0.0, 0.0)
    assert "blind" in command.reason
    # forward, where the lidar sees and nothing is there: no objection
    assert SafetyStop.decide(jackal_scan(), odom(0.3), JACKAL, {}) is None


def test_the_stopping_reach_includes_braking_at_the_robots_acceleration() -> None:
    # 2 m/s: footprint 0.22 + margin 0.06 + 2 x 0.2 s look-ahead + 2^2 / (2 x 10) braking
    # = 0.88 m; an obstacle 0.85 m ahead is within it, one 0.9 m ahead is not
    assert SafetyStop.decide(jackal_scan((-3.0, 3.0, 0.85)), odom(2.0), JACKAL, {}) is not None
    assert SafetyStop.decide(jackal_scan((-3.0, 3.0, 0.9)), odom(2.0), JACKAL, {}) is None
    # a robot that brakes at 1 m/s^2 needs 2 m more: 0.9 m ahead stops it
    slow = Robot("r1", 2.0, 4.0, 0.22, 270.0, max_linear_accel_mps2=1.0)
    assert SafetyStop.decide(jackal_scan((-3.0, 3.0, 0.9)), odom(2.0), slow, {}) is not None


def test_avoid_distances_follow_the_footprint() -> None:
    burger, jackal = AvoidParams.defaults(BURGER.footprint_radius_m), AvoidParams.defaults(0.22)
    assert (burger.distance_m, burger.lateral_m, burger.stop_distance_m) == (0.40, 0.25, 0.20)
    assert (jackal.distance_m, jackal.lateral_m, jackal.stop_distance_m) == (0.515, 0.365, 0.315)
    # 0.3 m to the front-right, 0.3 m off the line of travel: in a Jackal's way, not a Burger's
    sweep = jackal_scan((-45.0, -44.0, 0.43))
    assert decide_turn(ScanView(sweep), jackal) is not None
    assert decide_turn(ScanView(sweep), burger) is None

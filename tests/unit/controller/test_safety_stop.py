"""safety_stop on synthetic scans: it fires only in the direction of travel."""

from __future__ import annotations

import pytest

from common.contract.records import LaserScan, Odometry
from common.controller_core.scenario import Command
from services.controller.safety_stop import SafetyStop
from tests.unit.controller.scans import BURGER, odom, scan

AHEAD = (-10.0, 10.0, 0.14)  # inside footprint 0.105 + margin 0.06
BEHIND = [(170.0, 180.0, 0.14), (-180.0, -170.0, 0.14)]


def safety(sweep: LaserScan, odometry: Odometry | None, **params: object) -> Command | None:
    return SafetyStop.decide(sweep, odometry, BURGER, params)


def test_moving_forward_toward_an_obstacle_stops_and_turns_to_the_freer_side() -> None:
    command = safety(scan(AHEAD, (20, 60, 0.5)), odom(0.15))
    assert command is not None and command.linear == 0.0
    assert command.angular < 0  # the left is more obstructed: swing the front to the right
    assert "forward" in command.reason and "0.14 m" in command.reason
    command = safety(scan(AHEAD, (-60, -20, 0.5)), odom(0.15))
    assert command is not None and command.angular > 0


def test_only_the_direction_of_travel_counts() -> None:
    assert safety(scan(*BEHIND), odom(0.15)) is None  # forward, obstacle behind
    assert safety(scan(AHEAD), odom(-0.1)) is None  # backward, obstacle ahead
    backward = safety(scan(*BEHIND), odom(-0.1))
    assert backward is not None and backward.linear == 0.0 and "backward" in backward.reason
    assert safety(scan(AHEAD), odom(0.0, 1.5)) is None  # turning in place sweeps nothing new
    assert safety(scan(AHEAD), odom(0.0, 0.0)) is None  # standing still
    assert safety(scan(AHEAD), None) is None  # no odometry yet: no direction of travel


def test_the_swept_path_is_the_bodys_width() -> None:
    # Beside the robot, 4.5 cm outside its circle: driving forward passes it.
    assert safety(scan((85, 95, 0.15)), odom(0.15)) is None
    # Off to the side but within the body's width ahead: its front edge would hit it.
    assert safety(scan((38, 42, 0.15)), odom(0.15)) is not None
    # Ahead but beyond footprint + margin + look-ahead: not yet.
    assert safety(scan((-10, 10, 0.25)), odom(0.15)) is None


def test_the_reach_grows_with_speed_and_the_margin_param() -> None:
    near = scan((-5, 5, 0.19))  # 0.165 m + 0.22 m/s x 0.2 s = 0.209 m reach at full speed
    assert safety(near, odom(0.22)) is not None
    assert safety(near, odom(0.05)) is None
    assert safety(near, odom(0.05), safety_margin_m=0.1) is not None
    assert safety(near, odom(0.22), safety_lookahead_s=0.0) is None


def test_boxed_in_means_a_full_stop_even_when_not_moving() -> None:
    boxed = scan((-180, 180, 0.14))
    command = safety(boxed, odom(0.0, 1.0))
    assert command is not None and (command.linear, command.angular) == (0.0, 0.0)


def test_the_recovery_turn_respects_the_robot_limit() -> None:
    command = safety(scan(AHEAD), odom(0.2), safety_turn_rps=9.0)
    assert command is not None and abs(command.angular) == pytest.approx(2.84)

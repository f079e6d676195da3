"""How long safety_stop's stop lives, tick by tick: until the robot can have stopped and the
next scans are judged, never the usual 0.5 s on a fast lidar. A stop held 0.5 s after the
robot stood pinned a standing Jackal in a moving obstacle's line while dodge asked it to step
away (docs/BENCHMARKS.md, "Moving obstacles"). The Burger's 5 Hz lidar keeps 0.5 s."""

from __future__ import annotations

from dataclasses import replace
from typing import cast

import pytest

from common.contract.records import Robot
from common.controller_core.scenario import Host, ScenarioSpec
from services.controller.safety_stop import SafetyStop
from tests.unit.controller.scans import BURGER, odom, scan

# a Jackal-class robot (models/jackal.yaml's limits) behind the Burger's 360-beam sweep
JACKAL = replace(
    BURGER,
    max_linear_mps=2.0,
    max_angular_rps=4.0,
    footprint_radius_m=0.22,
    max_linear_accel_mps2=10.0,
)


def rule_for(robot: Robot) -> SafetyStop:
    spec = ScenarioSpec(robot, "GOTO_FAST", {})
    return SafetyStop(cast(Host, None), ("r1", "safety_stop"), spec)  # host: unused here


def test_a_stop_on_a_fast_lidar_lives_a_few_periods_or_the_braking_time() -> None:
    rule = rule_for(JACKAL)
    near = (-10.0, 10.0, 0.35)  # 0.35 m ahead: within reach (0.39 m at 0.5 m/s)
    # (t, measured speed, fires, ttl): the Jackal's lidar every 0.02 s, braking at 10 m/s^2
    ticks = [
        (10.00, 1.50, True, 0.5),  # first scan: its period not known yet, the usual 0.5 s
        (10.02, 1.30, True, 0.13),  # braking from 1.3 m/s takes 0.13 s (> 3 periods, 0.06)
        (10.04, 0.50, True, 0.1),  # 0.05 s to brake: the floor, 0.1 s
        (10.06, 0.00, False, None),  # standing: nothing swept, nothing said
        (10.08, 0.00, False, None),
    ]
    for i, (t, v, fires, ttl) in enumerate(ticks):
        sweep = scan(near, scan_id=i + 1, stamp=t)
        command = rule.judge(sweep, odom(v, 0.0, i + 1, t))
        assert (command is not None) == fires, t
        if command is not None:
            assert command.linear == 0.0
            assert rule.ttl_s() == pytest.approx(ttl), t
    # so the last stop (made at 10.04) ends at 10.14, 0.08 s after the robot stood: dodge's
    # step out of a mover's way, or dwa's next choice, is obeyed from then on


def test_a_slow_lidar_keeps_the_usual_half_second() -> None:
    rule = rule_for(BURGER)
    near = (-10.0, 10.0, 0.14)
    for i, t in enumerate((10.0, 10.2, 10.4)):  # the Burger's 5 Hz
        command = rule.judge(scan(near, scan_id=i + 1, stamp=t), odom(0.15, 0.0, i + 1, t))
        assert command is not None
        assert rule.ttl_s() == pytest.approx(0.5)  # 3 periods are 0.6 s: capped at 0.5

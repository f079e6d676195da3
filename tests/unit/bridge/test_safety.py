"""The safety layer's geometry, tick by tick: what the newest scan lets a command do."""

from __future__ import annotations

import math
from typing import Any

import pytest

from common import bus
from common.contract import keys
from common.errors import ConfigError
from services.bridge.safety import (
    CLEAR,
    LIMITED,
    STOPPED,
    UNCHECKED,
    SafetyLayer,
    SafetyParams,
    max_speed,
    stopping_m,
)
from services.bridge.sensor_payloads import LaserScan, parse_sensor
from services.bridge.settings import BridgeSettings

R = 0.105  # the burger's footprint radius
FULL = 0.22
DECEL = 2.5  # the burger's linear acceleration limit (its robot row): it brakes at that


def scan(stamp: float, *obstacles: tuple[float, float], robot: str = "r1") -> LaserScan:
    """A 360-beam scan (beam 0 ahead, counter-clockwise) with returns at (range, degrees)."""
    ranges = [math.inf] * 360
    for range_m, degrees in obstacles:
        ranges[round(degrees) % 360] = range_m
    return LaserScan(robot, stamp, 0, 0.0, 2 * math.pi / 360, 0.12, 3.5, ranges)


def layer(**params: float) -> SafetyLayer:
    return SafetyLayer(SafetyParams(**params))  # type: ignore[arg-type]


def test_an_obstacle_ahead_within_stopping_distance_stops_the_robot_and_says_why() -> None:
    safety = layer()
    safety.scan(scan(10.0, (0.14, 0.0)))
    verdict = safety.judge("r1", FULL, R, 10.05, DECEL)
    assert verdict.outcome == STOPPED and verdict.linear == 0.0
    assert verdict.reason.startswith("stopped: obstacle 0.14 m ahead at +0 deg")
    assert verdict.noted


def test_closer_than_the_full_stopping_distance_limits_to_a_speed_that_stops_in_time() -> None:
    p = SafetyParams()
    safety = SafetyLayer(p)
    safety.scan(scan(10.0, (0.18, 0.0)))
    verdict = safety.judge("r1", FULL, R, 10.0, DECEL)
    assert verdict.outcome == LIMITED and 0.0 < verdict.linear < FULL
    budget = 0.18 - R - p.margin_m
    assert stopping_m(verdict.linear, p.latency_s, DECEL) == pytest.approx(budget)
    assert verdict.reason.startswith(f"limited to {verdict.linear:.3f} m/s")
    # a speed already within what stops in time passes unchanged
    assert safety.judge("r1", verdict.linear * 0.99, R, 10.0, DECEL).outcome == CLEAR


def test_an_obstacle_farther_than_the_stopping_distance_leaves_the_command_unchanged() -> None:
    safety = layer()
    safety.scan(scan(10.0, (0.5, 0.0)))
    verdict = safety.judge("r1", FULL, R, 10.0, DECEL)
    assert (verdict.outcome, verdict.linear, verdict.noted) == (CLEAR, FULL, False)


def test_an_obstacle_behind_does_not_stop_a_robot_going_forward() -> None:
    safety = layer()
    safety.scan(scan(10.0, (0.13, 180.0)))
    assert safety.judge("r1", FULL, R, 10.0, DECEL).outcome == CLEAR


def test_reversing_toward_an_obstacle_behind_stops() -> None:
    safety = layer()
    safety.scan(scan(10.0, (0.13, 180.0)))
    verdict = safety.judge("r1", -FULL, R, 10.0, DECEL)
    assert verdict.outcome == STOPPED and verdict.linear == 0.0
    assert "behind" in verdict.reason


def test_an_obstacle_beside_the_swept_corridor_does_not_count() -> None:
    safety = layer()
    # 0.13 m away at 60 degrees: 0.113 m to the side, outside the 0.105 m footprint
    safety.scan(scan(10.0, (0.13, 60.0), (0.13, -60.0)))
    assert safety.judge("r1", FULL, R, 10.0, DECEL).outcome == CLEAR
    # at 40 degrees (0.084 m to the side) the body would touch it
    safety.scan(scan(10.1, (0.13, 40.0)))
    assert safety.judge("r1", FULL, R, 10.1, DECEL).outcome == STOPPED


def test_turning_in_place_always_passes() -> None:
    safety = layer()
    safety.scan(scan(10.0, *[(0.121, float(d)) for d in range(360)]))  # boxed in
    verdict = safety.judge("r1", 0.0, R, 10.0, DECEL)
    assert (verdict.outcome, verdict.linear) == (CLEAR, 0.0)


def test_the_distance_moved_since_the_scan_is_counted() -> None:
    """At 0.22 m/s the robot covers 4.4 cm between two 5 Hz scans: an obstacle that was
    clear of the stopping distance in the scan may no longer be."""
    safety = layer()
    safety.scan(scan(10.0, (0.215, 0.0)))
    assert safety.judge("r1", FULL, R, 10.0, DECEL).outcome == CLEAR  # fresh: 0.06 m to spare
    assert safety.judge("r1", FULL, R, 10.19, DECEL).outcome == LIMITED  # 4.2 cm later


def test_a_stale_scan_leaves_the_command_unchecked_by_default_and_says_so() -> None:
    safety = layer()
    assert (
        safety.judge("r1", FULL, R, 3.0, DECEL).reason
        == "unchecked: no scan within 0.5 s (no scan yet)"
    )
    safety.scan(scan(10.0, (0.13, 0.0)))
    verdict = safety.judge("r1", FULL, R, 10.6, DECEL)
    assert (verdict.outcome, verdict.linear) == (UNCHECKED, FULL)
    assert verdict.reason == "unchecked: no scan within 0.5 s (newest scan 0.60 s old)"
    assert verdict.noted


def test_a_blind_speed_cap_limits_or_stops_without_a_fresh_scan() -> None:
    capped = layer(blind_mps=0.05)
    verdict = capped.judge("r1", -FULL, R, 3.0, DECEL)
    assert (verdict.outcome, verdict.linear) == (LIMITED, -0.05)
    assert capped.judge("r1", 0.04, R, 3.0, DECEL).outcome == UNCHECKED
    stopped = layer(blind_mps=0.0)
    assert stopped.judge("r1", FULL, R, 3.0, DECEL).outcome == STOPPED


def test_no_clock_yet_takes_the_newest_scan_as_fresh() -> None:
    safety = layer()
    safety.scan(scan(10.0, (0.13, 0.0)))
    assert safety.judge("r1", FULL, R, None, DECEL).outcome == STOPPED


def test_an_older_scan_arriving_late_does_not_replace_the_newer() -> None:
    safety = layer()
    safety.scan(scan(10.2, (0.13, 0.0)))
    safety.scan(scan(10.0))  # reordered: clear, but older
    assert safety.judge("r1", FULL, R, 10.2, DECEL).outcome == STOPPED


def test_the_layer_turned_off_passes_everything() -> None:
    safety = layer(enabled=False)
    safety.scan(scan(10.0, (0.13, 0.0)))
    verdict = safety.judge("r1", FULL, R, 10.0, DECEL)
    assert (verdict.outcome, verdict.linear) == (CLEAR, FULL)


def test_robots_are_judged_on_their_own_scans() -> None:
    safety = layer()
    safety.scan(scan(10.0, (0.13, 0.0), robot="r1"))
    safety.scan(scan(10.0, robot="r2"))
    assert safety.judge("r1", FULL, R, 10.0, DECEL).outcome == STOPPED
    assert safety.judge("r2", FULL, R, 10.0, DECEL).outcome == CLEAR


def test_max_speed_inverts_the_stopping_distance() -> None:
    for budget in (0.001, 0.03, 0.2):
        v = max_speed(budget, 0.1, 2.5)
        assert stopping_m(v, 0.1, 2.5) == pytest.approx(budget)
    assert max_speed(0.0, 0.1, 2.5) == 0.0
    assert max_speed(-1.0, 0.1, 2.5) == 0.0


def test_the_settings_come_from_pnav_bridge_safety_variables() -> None:
    assert BridgeSettings.from_env({}).safety == SafetyParams()
    settings = BridgeSettings.from_env(
        {
            "PNAV_BRIDGE_SAFETY": "off",
            "PNAV_BRIDGE_SAFETY_DECEL_MPS2": "1.5",
            "PNAV_BRIDGE_SAFETY_LATENCY_S": "0.2",
            "PNAV_BRIDGE_SAFETY_MARGIN_M": "0",
            "PNAV_BRIDGE_SAFETY_SCAN_AGE_S": "1",
            "PNAV_BRIDGE_SAFETY_BLIND_MPS": "0",
        }
    )
    assert settings.safety == SafetyParams(False, 1.5, 0.2, 0.0, 1.0, 0.0)
    assert SafetyParams().decel_mps2 is None  # unset: each robot brakes at its own limit
    for name, raw in (
        ("PNAV_BRIDGE_SAFETY", "maybe"),
        ("PNAV_BRIDGE_SAFETY_DECEL_MPS2", "0"),
        ("PNAV_BRIDGE_SAFETY_MARGIN_M", "-0.1"),
        ("PNAV_BRIDGE_SAFETY_BLIND_MPS", "nan"),
    ):
        with pytest.raises(ConfigError, match=name):
            BridgeSettings.from_env({name: raw})


def test_the_stopping_distance_brakes_at_each_robots_own_acceleration_limit() -> None:
    safety = layer()
    # 0.3 m ahead of two robots at 0.22 m/s: free travel 0.195 m, 0.145 m once the margin
    # is kept. Braking at 2.5 m/s^2 needs 0.022 + 0.0097 m: clear; at 0.1 m/s^2 it needs
    # 0.022 + 0.242 m: the speed is limited to what stops in 0.145 m
    safety.scan(scan(10.0, (0.3, 0.0)))
    safety.scan(scan(10.0, (0.3, 0.0), robot="r2"))
    assert safety.judge("r1", FULL, R, 10.0, 2.5).outcome == CLEAR
    slow = safety.judge("r2", FULL, R, 10.0, 0.1)
    assert slow.outcome == LIMITED and "braking at 0.1 m/s^2" in slow.reason
    assert stopping_m(abs(slow.linear), 0.1, 0.1) == pytest.approx(0.3 - R - 0.05)


def test_the_variable_overrides_every_robots_deceleration() -> None:
    safety = layer(decel_mps2=0.1)
    safety.scan(scan(10.0, (0.3, 0.0)))
    # the robot could brake at 2.5 m/s^2, but the operator said to assume 0.1
    assert safety.judge("r1", FULL, R, 10.0, 2.5).outcome == LIMITED


def test_a_partial_field_of_view_checks_the_beams_it_has() -> None:
    # a 270-degree, 720-beam scan starting 135 degrees right of the heading (the Jackal's):
    # beam 359.5 is straight ahead
    ranges = [math.inf] * 720
    ranges[359] = ranges[360] = 0.5
    inc = math.radians(270.0) / 719
    record = LaserScan("j", 10.0, 0, math.radians(-135.0), inc, 0.1, 30.0, ranges)
    safety = layer()
    safety.scan(record)
    verdict = safety.judge("j", 2.0, 0.22, 10.0, 10.0)
    # free travel 0.28 m, minus the margin: 0.23 m; 2 m/s needs 0.2 + 0.2 m at 10 m/s^2
    assert verdict.outcome == LIMITED
    assert stopping_m(verdict.linear, 0.1, 10.0) == pytest.approx(0.5 - 0.22 - 0.05, abs=1e-3)


def test_a_validated_scan_is_judged_as_the_same_scan_built_by_hand() -> None:
    # the bridge's records carry their ranges as an array too (parse_scan); the verdicts and
    # the reasons they give must not depend on which the layer started from
    obstacles = ((0.31, 2.0), (0.5, -8.0), (0.25, 181.0), (0.12, 95.0))
    by_hand = scan(1.0, *obstacles)
    validated = parse_sensor(
        keys.SCAN,
        keys.robot_key("r1", keys.SCAN),
        bus.pack({**_scan_body(by_hand), "seq": 0}),
        {"r1": 360},
    )
    assert isinstance(validated, LaserScan) and validated.array is not None
    for linear in (0.22, 0.1, -0.22, 0.05, 0.0):
        one, other = layer(), layer()
        one.scan(by_hand)
        other.scan(validated)
        assert other.judge("r1", linear, R, 1.05, DECEL) == one.judge("r1", linear, R, 1.05, DECEL)


def _scan_body(record: LaserScan) -> dict[str, object]:
    fields = ("stamp", "angle_min", "angle_increment", "range_min", "range_max", "ranges")
    return {name: getattr(record, name) for name in fields}


def test_a_polygon_is_measured_from_its_edge_not_a_disc() -> None:
    from common.footprint import Footprint

    box = Footprint.of(0.22, ((0.254, -0.215), (0.254, 0.215), (-0.254, 0.215), (-0.254, -0.215)))
    # a return 0.40 m ahead and 0.21 m left: 0.146 m from the box's flat front, which a disc
    # of 0.22 m would put at 0.40 - sqrt(0.22^2 - 0.21^2) = 0.334 m
    at = (math.hypot(0.40, 0.21), math.degrees(math.atan2(0.21, 0.40)))
    disc_layer, box_layer = layer(), layer()
    for safety in (disc_layer, box_layer):
        safety.scan(scan(10.0, at))
    # 0.5 m/s needs 0.05 + 0.05 + 0.05 m margin of room braking at 2.5 m/s^2
    assert disc_layer.judge("r1", 0.5, 0.22, 10.0, DECEL).outcome == CLEAR
    verdict = box_layer.judge("r1", 0.5, box, 10.0, DECEL)
    assert verdict.outcome == LIMITED and "polygon" in verdict.reason
    free, _, _ = box_layer.scans["r1"].free_travel(1, box)
    assert free == pytest.approx(0.40 - 0.254, abs=0.01)  # the 1-degree beam rounds y a little
    # a return beside the box (0.218 m left, clear of its 0.215 m side) is no obstacle
    # ahead, though the disc of the same row (0.22 m) meets it
    beside = layer()
    beside.scan(scan(10.0, (0.371, 36.0)))
    assert beside.judge("r1", 1.0, box, 10.0, DECEL).outcome == CLEAR
    assert beside.judge("r1", 1.0, 0.22, 10.0, DECEL).outcome != CLEAR
    # backing up: measured from the back edge
    behind = layer()
    behind.scan(scan(10.0, (0.5, 180.0)))
    free_back, _, _ = behind.scans["r1"].free_travel(-1, box)
    assert free_back == pytest.approx(0.5 - 0.254)


def test_a_polygon_turning_as_it_drives_is_judged_along_its_arc() -> None:
    from common.footprint import Footprint

    box = Footprint.of(0.22, ((0.254, -0.215), (0.254, 0.215), (-0.254, 0.215), (-0.254, -0.215)))
    # a return ahead on the left, beside the straight corridor (0.35 m > the 0.215 m flank):
    # driving straight or turning right passes it, turning left at 1 rad/m swings the front
    # left corner into it about 0.4 m on
    at = (math.hypot(0.6, 0.35), math.degrees(math.atan2(0.35, 0.6)))
    outcomes = {}
    for angular in (0.0, -1.5, 1.5):
        safety = layer()
        safety.scan(scan(10.0, at))
        outcomes[angular] = safety.judge("r1", 1.5, box, 10.0, DECEL, angular)
    assert outcomes[0.0].outcome == CLEAR and outcomes[-1.5].outcome == CLEAR
    assert outcomes[1.5].outcome in (LIMITED, STOPPED)
    assert outcomes[1.5].linear < 1.5
    travel, _, bearing = layer_scan(at).arc_travel(box, 1, 1.0, 1.0)
    assert 0.3 < travel < 0.5 and bearing == pytest.approx(at[1], abs=1.0)
    # backing up while turning: the arc runs behind
    travel_back, _, _ = layer_scan((0.5, 180.0)).arc_travel(box, -1, 0.5, 1.0)
    assert 0.2 < travel_back < 0.26


def layer_scan(*obstacles: tuple[float, float]) -> Any:
    safety = layer()
    safety.scan(scan(10.0, *obstacles))
    return safety.scans["r1"]


def test_a_polygon_is_not_turned_into_what_its_corner_would_hit() -> None:
    from common.footprint import Footprint

    box = Footprint.of(0.22, ((0.254, -0.215), (0.254, 0.215), (-0.254, 0.215), (-0.254, -0.215)))
    # a post 0.34 m out at 45 degrees left: a left turn swings the front left corner past it
    # within 1 cm, a right turn swings nothing that far out near it
    post = (0.34, 45.0)
    left, right, disc = layer(), layer(), layer()
    for safety in (left, right, disc):
        safety.scan(scan(10.0, post))
    stopped = left.judge("r1", 0.0, box, 10.0, DECEL, 4.0)
    assert (
        stopped.angular == 0.0 and stopped.outcome == LIMITED and "turn stopped" in stopped.reason
    )
    turned = right.judge("r1", 0.0, box, 10.0, DECEL, -4.0)
    assert turned.angular is None and turned.outcome == CLEAR
    # a disc's turn sweeps nothing
    assert disc.judge("r1", 0.0, 0.22, 10.0, DECEL, 4.0).angular is None

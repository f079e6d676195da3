"""Speed zones in the safety layer, tick by tick: inside one the linear speed sent is capped
at the zone's max_speed_mps whatever was decided; the scan may lower it further; outside,
and for a robot the zone is not for, commands pass as before."""

from __future__ import annotations

import math

from common.contract.zones import KEEPOUT, SPEED_LIMIT, Zone
from services.bridge.safety import CLEAR, LIMITED, STOPPED, SafetyLayer, SafetyParams
from services.bridge.sensor_payloads import LaserScan
from services.bridge.speed_zones import Cap, SpeedZones

R = 0.105
DECEL = 2.5
AISLE = Zone("aisle", SPEED_LIMIT, (0.0, 4.0, 4.0, 0.0), (-1.0, -1.0, 1.0, 1.0), 0.3)
SLOWER = Zone("crossing", SPEED_LIMIT, (1.0, 2.0, 2.0, 1.0), (-1.0, -1.0, 1.0, 1.0), 0.1)


def clear_scan(stamp: float) -> LaserScan:
    return LaserScan("r1", stamp, 0, 0.0, 2 * math.pi / 360, 0.12, 3.5, [math.inf] * 360)


def layer(*zones: Zone, **params: bool) -> SafetyLayer:
    safety = SafetyLayer(SafetyParams(**params))  # type: ignore[arg-type]
    safety.zones.set(list(zones))
    safety.scan(clear_scan(10.0))
    return safety


def test_inside_a_speed_zone_the_speed_sent_is_capped_and_the_reason_names_the_zone() -> None:
    safety = layer(AISLE)
    safety.zones.pose("r1", 10.0, 0.5, 0.0)
    verdict = safety.judge("r1", 1.5, R, 10.0, DECEL)
    assert verdict.outcome == LIMITED and verdict.linear == 0.3
    assert verdict.zone == "aisle" and verdict.noted
    assert (
        verdict.reason == "limited to 0.3 m/s: speed zone 'aisle' caps 0.3 m/s (1.500 m/s decided)"
    )
    # backwards too, and a speed already under the cap passes unchanged
    assert safety.judge("r1", -1.0, R, 10.0, DECEL).linear == -0.3
    under = safety.judge("r1", 0.2, R, 10.0, DECEL)
    assert (under.outcome, under.linear, under.zone) == (CLEAR, 0.2, None)


def test_tick_by_tick_the_cap_starts_at_the_zone_edge_and_ends_past_it() -> None:
    safety = layer(AISLE)
    sent = []
    for tick in range(12):  # the robot's centre from x = -1.0 to 4.5, 0.5 m a tick
        x = -1.0 + 0.5 * tick
        stamp = 10.0 + 0.1 * tick
        safety.scan(clear_scan(stamp))
        safety.zones.pose("r1", stamp, x, 0.0)
        sent.append((x, safety.judge("r1", 1.0, R, stamp, DECEL).linear))
    assert [v for x, v in sent if x < 0.0 or x > 4.0] == [1.0] * 3
    assert [v for x, v in sent if 0.0 < x < 4.0] == [0.3] * 7


def test_where_zones_overlap_the_lowest_cap_wins() -> None:
    safety = layer(AISLE, SLOWER)
    safety.zones.pose("r1", 10.0, 1.5, 0.0)
    verdict = safety.judge("r1", 1.0, R, 10.0, DECEL)
    assert (verdict.linear, verdict.zone) == (0.1, "crossing")


def test_the_scan_may_lower_a_capped_speed_further_and_both_reasons_are_kept() -> None:
    safety = layer(AISLE)
    ranges = [math.inf] * 360
    ranges[0] = 0.14  # an obstacle just ahead: stop
    safety.scan(LaserScan("r1", 10.0, 0, 0.0, 2 * math.pi / 360, 0.12, 3.5, ranges))
    safety.zones.pose("r1", 10.0, 0.5, 0.0)
    verdict = safety.judge("r1", 1.0, R, 10.0, DECEL)
    assert verdict.outcome == STOPPED and verdict.linear == 0.0 and verdict.zone == "aisle"
    assert verdict.reason.startswith("stopped: obstacle") and "speed zone 'aisle'" in verdict.reason


def test_the_cap_holds_with_the_scan_check_off_and_without_a_scan() -> None:
    safety = layer(AISLE, enabled=False)
    safety.zones.pose("r1", 10.0, 0.5, 0.0)
    assert safety.judge("r1", 1.0, R, 10.0, DECEL).linear == 0.3
    blind = SafetyLayer(SafetyParams())
    blind.zones.set([AISLE])
    blind.zones.pose("r1", 10.0, 0.5, 0.0)
    verdict = blind.judge("r1", 1.0, R, 10.0, DECEL)
    assert verdict.linear == 0.3 and verdict.outcome == LIMITED
    assert "unchecked: no scan" in verdict.reason


def test_a_zone_for_another_robot_a_keepout_zone_and_no_pose_cap_nothing() -> None:
    theirs = Zone("theirs", SPEED_LIMIT, AISLE.xs, AISLE.ys, 0.3, robot_id="r2")
    keepout = Zone("k", KEEPOUT, AISLE.xs, AISLE.ys)
    safety = layer(theirs, keepout)
    assert safety.judge("r1", 1.0, R, 10.0, DECEL).linear == 1.0  # no pose yet
    safety.zones.pose("r1", 10.0, 0.5, 0.0)
    assert safety.judge("r1", 1.0, R, 10.0, DECEL).linear == 1.0
    assert safety.zones.zones == (theirs,)  # keepout zones are the planner's


def test_an_older_pose_does_not_replace_a_newer_one() -> None:
    zones = SpeedZones()
    zones.set([AISLE])
    zones.pose("r1", 10.0, 0.5, 0.0)
    zones.pose("r1", 9.0, -3.0, 0.0)
    assert zones.cap("r1") == Cap(0.3, "aisle")


def test_the_cap_agrees_with_each_zones_own_inside_test_on_random_star_zones() -> None:
    import numpy as np

    rng = np.random.default_rng(3)
    stars = []
    for i in range(40):
        n = int(rng.integers(3, 30))
        angles = np.sort(rng.uniform(0, 2 * np.pi, n))
        radii = rng.uniform(0.5, 3.0, n)
        cx, cy = rng.uniform(0, 10, 2)
        xs = tuple(float(v) for v in cx + radii * np.cos(angles))
        ys = tuple(float(v) for v in cy + radii * np.sin(angles))
        stars.append(Zone(f"z{i}", SPEED_LIMIT, xs, ys, float(rng.uniform(0.1, 2.0))))
    zones = SpeedZones()
    zones.set(stars)
    for k in range(300):
        x, y = rng.uniform(-2, 12, 2)
        zones.pose("r1", float(k), float(x), float(y))
        inside = [z for z in stars if z.contains(float(x), float(y))]
        best = min(inside, key=lambda z: z.max_speed_mps or 0.0) if inside else None
        expected = None if best is None else Cap(best.max_speed_mps or 0.0, best.name)
        assert zones.cap("r1") == expected, (x, y)

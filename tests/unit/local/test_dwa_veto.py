"""dwa with a footprint polygon never recommends what the bridge's safety layer would stop.

The layer (services/bridge/safety.py) judges a polygon's command along its arc and through its
turn; dwa's roll-out poses are coarser. A Jackal wedged beside a post kept choosing a hard
turn that swung its rear corner into the post, the layer stopped it every time, and recovery
gave up (BARN's hard worlds). pnav_local/veto.py puts dwa's winner to the layer's own test."""

from __future__ import annotations

import math

import numpy as np

from common import sweep
from common.contract.records import LaserScan as ScanRow
from common.footprint import Footprint
from pnav_local import veto
from pnav_local.dwa import choose, command_for
from pnav_local.dwa_params import DwaParams
from services.bridge.safety import CLEAR, SafetyLayer, SafetyParams
from services.bridge.sensor_payloads import LaserScan
from tests.unit.local.test_dwa_reference import BOX, JACKAL, ROWS, scene

BOX_FOOT = Footprint.of(JACKAL.footprint_radius_m, BOX)
BEAMS, FOV = 720, math.radians(270.0)


def layer_verdict(scan: ScanRow, linear: float, angular: float) -> str:
    """What the bridge's layer does with the command against this scan, just taken."""
    layer = SafetyLayer(SafetyParams())
    layer.scan(LaserScan("r1", scan.stamp, 0, scan.angle_min, scan.angle_increment,
                         scan.range_min, 10.0, scan.ranges.astype(float).tolist()))  # fmt: skip
    verdict = layer.judge("r1", linear, BOX_FOOT, scan.stamp, JACKAL.max_linear_accel_mps2,
                          angular)  # fmt: skip
    return verdict.outcome


def post_at(range_m: float, bearing_deg: float) -> ScanRow:
    """A scan seeing only one thin post at (range, bearing), a few beams wide."""
    angles = -FOV / 2 + FOV / (BEAMS - 1) * np.arange(BEAMS)
    ranges = np.full(BEAMS, np.inf)
    near = np.abs(angles - math.radians(bearing_deg)) <= math.radians(1.0)
    ranges[near] = range_m
    return ScanRow(1, "r1", 1.0, -FOV / 2, FOV / (BEAMS - 1), 0.1, 10.0, ranges.astype("f4"))


def test_a_hard_turn_beside_a_post_is_refused_by_both_and_driving_on_is_not() -> None:
    # the Jackal of barn_hard_002: a post 0.30 m away at +117 deg, 5 cm off its left side
    scan = post_at(0.30, 117.0)
    returns = sweep.Returns.of_ranges(
        scan.ranges.astype(np.float64), scan.angle_min, scan.angle_increment, scan.range_min
    )

    decel = JACKAL.max_linear_accel_mps2

    def passes(v: float, w: float) -> bool:
        return sweep.passes(returns, BOX_FOOT, v, w, margin_m=sweep.MARGIN_M,
                            latency_s=sweep.LATENCY_S, decel_mps2=decel)  # fmt: skip

    assert not passes(0.5, -4.0)  # the rear-left corner swings into the post
    assert layer_verdict(scan, 0.5, -4.0) != CLEAR
    assert passes(0.5, 0.0)  # straight on, the side slides past it
    assert layer_verdict(scan, 0.5, 0.0) == CLEAR
    assert passes(0.5, 1.0)  # turning away from it
    assert layer_verdict(scan, 0.5, 1.0) == CLEAR


def test_the_veto_takes_the_best_arc_that_passes() -> None:
    scan = post_at(0.30, 117.0)
    v = np.array([0.5, 0.5, 0.5])
    w = np.array([-4.0, 0.0, 1.0])
    total = np.array([3.0, 2.0, 1.0])
    ok = np.array([True, True, True])
    # the best (a hard right) is refused; the next (straight on) passes
    assert veto.winner(0, total, ok, v, w, scan, JACKAL, BOX_FOOT) == (1, 1)
    # an inadmissible arc is never taken, however it would fare
    ok = np.array([True, False, True])
    assert veto.winner(0, total, ok, v, w, scan, JACKAL, BOX_FOOT) == (2, 1)
    # a disc is never vetoed: its turn sweeps nothing
    disc = Footprint.of(JACKAL.footprint_radius_m, None)
    assert veto.winner(0, total, ok, v, w, scan, JACKAL, disc) == (0, 0)


def test_dwa_with_the_box_never_recommends_what_the_layer_would_change() -> None:
    rng = np.random.default_rng(31)
    moving = 0
    for i in range(60):
        scan, odom, path = scene(rng, i + 1)
        p = DwaParams.read(ROWS[i % len(ROWS)])
        choice = choose(scan, odom, JACKAL, path, p, BOX)
        if choice is None:
            continue
        command = command_for(choice, path)
        if command.linear == 0.0 and command.angular == 0.0:
            continue
        moving += 1
        assert layer_verdict(scan, command.linear, command.angular) == CLEAR, (i, command)
    assert moving > 30

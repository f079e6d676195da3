"""dwa with a polygon footprint: a roll-out pose collides when a hit lies inside the
outline placed at that pose (or within the margin), so a box that fits a gap straight on
is refused the same gap at an angle, where the disc of its inscribed radius would pass."""

from __future__ import annotations

import math

import numpy as np
import pytest

import pnav_local.clearance as clearance
from common.contract.planned_path import PlannedPath
from common.contract.records import LaserScan, Odometry, Robot
from pnav_local.dwa import choose
from pnav_local.dwa_params import DwaParams
from tests.unit.local import dwa_reference

JACKAL = Robot(
    "r1", 2.0, 4.0, 0.215, 270.0, max_linear_accel_mps2=10.0, max_angular_accel_rps2=20.0
)
BOX = ((-0.254, -0.215), (0.254, -0.215), (0.254, 0.215), (-0.254, 0.215))  # 0.508 x 0.430 m
BEAMS, FOV = 720, math.radians(270.0)
# a doorway 0.6 m wide in a thin wall along x = 0 and the robot standing in it, facing
# through: the box (half-width 0.215 m) drives on straight with 8.5 cm each side, but its
# corners, 0.333 m from its centre, sweep through the door's jambs when it turns in the
# doorway; the disc of its inscribed radius may turn there
JAMBS = ((-0.05, 0.05, 0.3, 3.0), (-0.05, 0.05, -3.0, -0.3))  # x0, x1, y0, y1: a 10 cm wall


def doorway_scan() -> LaserScan:
    """The wall as a 720-beam lidar at the origin facing +x sees it (rays against boxes)."""
    angles = -FOV / 2 + FOV / (BEAMS - 1) * np.arange(BEAMS)
    dx, dy = np.cos(angles), np.sin(angles)
    ranges = np.full(BEAMS, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for x0, x1, y0, y1 in JAMBS:
            tx0, tx1 = x0 / dx, x1 / dx
            ty0, ty1 = y0 / dy, y1 / dy
            near = np.maximum(np.minimum(tx0, tx1), np.minimum(ty0, ty1))
            far = np.minimum(np.maximum(tx0, tx1), np.maximum(ty0, ty1))
            hit = (far >= near) & (near > 0)
            ranges = np.where(hit, np.minimum(ranges, near), ranges)
    return LaserScan(1, "r1", 1.0, -FOV / 2, FOV / (BEAMS - 1), 0.05, 10.0, ranges.astype("f4"))


def admitted(polygon: tuple[tuple[float, float], ...] | None) -> tuple[bool, bool]:
    """Whether dwa admits (driving straight on, turning in the doorway) for the robot
    standing in it, and that the plain reference agrees arc by arc."""
    scan = doorway_scan()
    odom = Odometry(1, "r1", 1.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    path = PlannedPath(1, "r1", 1.0, 1, "goal", 3.0, 0.0, (0.0, 3.0), (0.0, 0.0), 3.0)
    p = DwaParams.read({"dwa_margin_m": 0.01, "dwa_delay_s": 0.0})
    choice = choose(scan, odom, JACKAL, path, p, polygon)
    plain = dwa_reference.choose(scan, odom, JACKAL, path, p, polygon)
    assert choice is not None and plain is not None
    assert plain.ok.tolist() == choice.ok.tolist() and plain.best == choice.best
    # the single arcs (a box's two-segment roll-outs come after them: they turn later)
    n = choice.window.arcs
    v, w, ok = choice.window.v[:n], choice.window.w[:n], choice.ok[:n]
    straight = (w == 0.0) & (v > 0.0)
    turning = (v == 0.0) & (np.abs(w) >= 1.0)  # in place, a quarter turn or more
    assert straight.any() and turning.any()
    return bool(ok[straight].all()), bool(ok[turning].any())


def test_a_box_fits_the_doorway_straight_on_but_not_turned_in_it() -> None:
    assert admitted(BOX) == (True, False)
    # the disc of the box's inscribed radius may do both: the corners are what hit
    assert admitted(None) == (True, True)


def test_the_polygon_gap_is_signed_and_turns_with_the_pose() -> None:
    box = clearance.Footprint.of(0.215, BOX)
    assert box.reach_m == pytest.approx(math.hypot(0.254, 0.215))
    hits = np.array([[0.3, 0.0], [0.0, 0.1]])
    # facing +x: 4.6 cm ahead of the front edge; the second hit is inside (0.115 m deep)
    gaps = clearance.gaps(np.array([0.0]), np.array([0.0]), np.array([0.0]), hits[:1], box, 1.0)
    assert gaps[0] == pytest.approx(0.046)
    inside = clearance.gaps(np.array([0.0]), np.array([0.0]), np.array([0.0]), hits[1:], box, 1.0)
    assert inside[0] == pytest.approx(-0.115)
    # turned 90 degrees, the same hit is off the robot's right side (half-width 0.215)
    turned = clearance.gaps(
        np.array([0.0]), np.array([0.0]), np.array([math.pi / 2]), hits[:1], box, 1.0
    )
    assert turned[0] == pytest.approx(0.3 - 0.215)
    rng = np.random.default_rng(4)
    xs, ys, yaws = (
        rng.uniform(-2, 2, (50, 8)),
        rng.uniform(-2, 2, (50, 8)),
        rng.uniform(-4, 4, (50, 8)),
    )
    pts = rng.uniform(-3, 3, (40, 2))
    fast = clearance.gaps(xs, ys, yaws, pts, box, 0.5)
    plain = dwa_reference.gaps(xs, ys, yaws, pts, 0.215, BOX)
    near = plain < 0.5
    assert near.any() and (~near).any()
    assert fast[near] == pytest.approx(plain[near], abs=1e-12)
    assert (fast[~near] >= 0.5).all()  # beyond what was asked: at least that far

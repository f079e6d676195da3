"""learned_drive's check (pnav_learned.candidates): the network proposes, dwa's geometry
checks. Scans are made from points in the robot's frame, the Jackal's box as the footprint."""

from __future__ import annotations

import math

import numpy as np
import pytest

import pnav_local.clearance as clearance
import pnav_local.trajectories as tr
from common.contract.records import LaserScan, Odometry, Robot
from pnav_learned.candidates import _outline, bounds, check, gaps, hits
from pnav_local.dwa_params import DwaParams

BOX = ((-0.254, -0.215), (0.254, -0.215), (0.254, 0.215), (-0.254, 0.215))
JACKAL = Robot("r1", 2.0, 4.0, 0.22, 270.0, 10.0, 20.0, BOX)
BEAMS = 1440
P = DwaParams()
OUTLINE = _outline(JACKAL.footprint_radius_m, BOX)


def scan_of(points: list[tuple[float, float]]) -> LaserScan:
    """A 360-degree scan that sees exactly these points (one per beam, nearest kept)."""
    inc = 2.0 * math.pi / BEAMS
    ranges = np.full(BEAMS, np.inf, dtype=np.float32)
    for x, y in points:
        i = round((math.atan2(y, x) + math.pi) / inc) % BEAMS
        ranges[i] = min(float(ranges[i]), math.hypot(x, y))
    return LaserScan(1, "r1", 0.0, -math.pi, inc, 0.05, 30.0, ranges)


def odom(v: float = 1.0, w: float = 0.0) -> Odometry:
    return Odometry(1, "r1", 0.0, 0.0, 0.0, 0.0, v, w)


def wall(x: float, y0: float, y1: float) -> list[tuple[float, float]]:
    return [(x, float(y)) for y in np.arange(y0, y1 + 1e-9, 0.02)]


def test_a_clear_proposal_is_recommended_as_it_is() -> None:
    verdict = check((1.5, 0.2), scan_of(wall(4.0, -2.0, 2.0)), odom(), JACKAL, P, 10.0, BOX)
    assert (verdict.rank, verdict.linear, verdict.angular) == (0, 1.5, 0.2)
    assert verdict.checked == 1  # the proposal passed: no neighbour was rolled out


def test_a_proposal_whose_swept_box_meets_a_point_is_refused() -> None:
    # one post straight ahead, 1.2 m off: driving straight at 1.5 m/s sweeps the box into it
    post = [(1.2, 0.0)]
    verdict = check((1.5, 0.0), scan_of(post), odom(1.5), JACKAL, P, 10.0, BOX)
    assert verdict.rank not in (None, 0)
    assert (verdict.linear, verdict.angular) != (1.5, 0.0)
    # what was chosen instead keeps the margin from the post along its whole arc
    win = tr.Window(np.array([verdict.linear]), np.array([verdict.angular]))
    start = tr.start_pose(1.5, 0.0, P.delay_s)
    poses = tr.rollout(win, start, P.horizon_s, P.steps)
    flat = tuple(p.ravel() for p in poses)
    foot_gaps = gaps(flat, (np.array([1.2]), np.array([0.0])), *OUTLINE, needed_m=0.06)
    assert foot_gaps.min() >= P.margin_m
    # the same post 0.6 m to the side of the arc is no reason to refuse it
    aside = check((1.5, 0.0), scan_of([(1.2, 0.215 + 0.6)]), odom(1.5), JACKAL, P, 10.0, BOX)
    assert aside.rank == 0


def test_the_box_not_the_disc_is_checked() -> None:
    # a post 0.30 m to the left: the 0.22 m disc turns in place clear of it, the box's
    # corners (0.33 m from the centre) swing into it
    post = [(0.0, 0.30)]
    disc = check((0.0, 2.0), scan_of(post), odom(0.0), JACKAL, P, 10.0, None)
    boxed = check((0.0, 2.0), scan_of(post), odom(0.0), JACKAL, P, 10.0, BOX)
    assert disc.rank == 0
    assert boxed.rank != 0
    assert (boxed.linear, boxed.angular) != (0.0, 2.0)


def test_boxed_in_none_is_admissible_and_the_verdict_is_a_brake() -> None:
    # the box hemmed in on every side 3 cm beyond its outline: forward meets the front wall,
    # turning swings the corners into the side walls
    gap = 0.03
    x, y = 0.254 + gap, 0.215 + gap
    pen = (
        wall(x, -y, y)
        + wall(-x, -y, y)
        + [(float(a), y) for a in np.arange(-x, x + 1e-9, 0.02)]
        + [(float(a), -y) for a in np.arange(-x, x + 1e-9, 0.02)]
    )
    verdict = check((0.5, 3.0), scan_of(pen), odom(0.0, 0.0), JACKAL, P, 10.0, BOX)
    assert verdict.rank is None
    assert (verdict.linear, verdict.angular) == (0.0, 0.0)
    assert verdict.checked > 1  # the neighbours were tried before giving up


def test_standing_still_is_no_move_while_a_move_passes() -> None:
    # a wall 0.45 m ahead, from a standstill: nothing near straight on passes, standing still
    # would, and so do sharp turns (the corners, 0.33 m out, keep 0.12 m): one is chosen
    verdict = check((1.0, 0.0), scan_of(wall(0.45, -1.5, 1.5)), odom(0.0), JACKAL, P, 10.0, BOX)
    assert verdict.rank not in (None, 0)
    assert abs(verdict.angular) >= 1.0
    assert verdict.checked > 17  # beyond the nearest few, into the rest of dwa's lattice


@pytest.mark.parametrize(
    ("v", "w", "cap"), [(0.0, 0.0, 9.0), (1.7, -3.5, 9.0), (0.5, 1.0, 0.3), (2.0, 4.0, 0.0)]
)
def test_the_window_is_the_one_dwa_samples(v: float, w: float, cap: float) -> None:
    lattice = tr.window(
        v, w, max_v=JACKAL.max_linear_mps, max_w=JACKAL.max_angular_rps,
        accel_v=JACKAL.max_linear_accel_mps2, accel_w=JACKAL.max_angular_accel_rps2,
        dt=P.window_s, v_samples=P.linear_samples, w_samples=P.angular_samples, v_cap=cap,
    )  # fmt: skip
    expected = (lattice.v.min(), lattice.v.max(), lattice.w.min(), lattice.w.max())
    assert bounds(odom(v, w), JACKAL, P, cap) == pytest.approx(expected)


def test_hits_are_the_points_within_reach() -> None:
    xs, ys = hits(scan_of([(1.0, 0.0), (0.0, 2.0), (-3.0, 0.0)]), 2.5)
    assert sorted(zip(np.round(xs, 3), np.round(ys, 3), strict=True)) == [(0.0, 2.0), (1.0, 0.0)]


@pytest.mark.parametrize("polygon", [BOX, None])
def test_gaps_are_clearances_below_what_the_margin_reads(polygon: object) -> None:
    # the check measures only the (pose, point) pairs within reach: below what the margin
    # reads it says what pnav_local.clearance says, above it at least that much
    rng = np.random.default_rng(3)
    foot, box = _outline(JACKAL.footprint_radius_m, polygon)  # type: ignore[arg-type]
    needed = P.margin_m + 0.01
    for _ in range(20):
        xs, ys, yaws = (
            rng.uniform(-1.5, 1.5, 40),
            rng.uniform(-1.5, 1.5, 40),
            rng.uniform(-4, 4, 40),
        )
        poses = (xs, ys, yaws)
        points = (rng.uniform(-2.0, 2.0, 25), rng.uniform(-2.0, 2.0, 25))
        got = gaps(poses, points, foot, box, needed)  # type: ignore[arg-type]
        want = clearance.gaps(*poses, np.column_stack(points), foot, needed)
        close = want < needed
        assert close.any() and (~close).any()
        assert np.array_equal(got[close], want[close])
        assert np.all(got[~close] >= needed)

"""The tracker's circle fit, scan by scan: a slow cylinder crossing the line of sight slides
along its own surface (the surface test cannot tell it from a standing one), but the centre
of the circle its arc fits moves; a standing cylinder's centre stays put however the robot
passes it, and a box's faces fit no circle."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pnav_local.tracks import DISPLACED_M, Tracker, _circle
from tests.unit.local.scene import Disc, box
from tests.unit.local.test_dodge import CORRIDOR, PERIOD, drive


@pytest.mark.parametrize("vx", [-0.2, 0.2, -0.3])
def test_a_slow_cylinder_crossing_ahead_is_told_moving_within_half_a_second(vx: float) -> None:
    # dynabarn_medium_004's mover_02: 0.195 m, 0.195 m/s, across the robot's way 4.3 m ahead
    mover = Disc(3.6 if vx < 0 else 1.2, 5.0, 0.195, vx=vx)
    first = None
    # each prefix of the run replayed from scratch (the tracker is deterministic): the first
    # scan after which it counts as moving
    for n in range(1, 41):
        tracker = Tracker()
        drive(tracker, [mover], CORRIDOR, start=(2.4, 0.7), speed=1.5, ticks=n)
        if tracker.moving():
            first = n
            break
    assert first is not None, "the slow mover was never told from a standing post"
    assert first * PERIOD <= 0.5
    (track,) = tracker.moving()
    assert track.vx == pytest.approx(vx, abs=0.06)


def test_a_standing_cylinder_passed_at_top_speed_never_moves() -> None:
    posts = [Disc(3.3, 2.0, 0.1), Disc(1.5, 3.4, 0.2), Disc(3.4, 6.8, 0.15), Disc(3.2, 4.5, 0.3)]
    tracker = Tracker()
    ticks = drive(tracker, posts, CORRIDOR, start=(2.4, 0.7), speed=2.0, ticks=150)
    assert all(command is None for _, command, _ in ticks)
    assert tracker.moving() == []


def test_the_circle_fit_finds_a_cylinders_centre_and_refuses_a_boxs_corner() -> None:
    # an arc of a 0.19 m circle as a scan sees it (the near side, 1 mm noise)
    rng = np.random.default_rng(3)
    a = np.linspace(-1.2, 1.2, 14) + math.pi
    r = 0.19 + rng.normal(0.0, 0.001, a.shape)
    centre = _circle(2.0 + r * np.cos(a), 1.0 + r * np.sin(a))
    assert centre is not None
    assert centre == pytest.approx((2.0, 1.0), abs=DISPLACED_M / 4)
    # a 0.3 m box's corner seen at 45 degrees: two faces, no circle
    (x0, y0, x1, y1), (_, _, x2, y2) = box(2.0, 1.0, 0.15)[:2]
    corner = np.array(
        [[x0 + (x1 - x0) * k / 6, y0 + (y1 - y0) * k / 6] for k in range(7)]
        + [[x1 + (x2 - x1) * k / 6, y1 + (y2 - y1) * k / 6] for k in range(1, 7)]
    )
    assert _circle(corner[:, 0], corner[:, 1]) is None
    assert _circle(np.linspace(0, 0.5, 10), np.full(10, 1.0)) is None, "a straight face"

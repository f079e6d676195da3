"""Where dwa faces along a path that bends: the carrot while the line to it follows the path,
else where the path bends out of sight (trajectories.sighted), tick by tick."""

from __future__ import annotations

import math

import numpy as np
import pytest

import pnav_local.trajectories as tr
from common.contract.planned_path import PlannedPath
from common.contract.records import Odometry, Robot
from pnav_local.dwa import choose, command_for
from pnav_local.dwa_params import DwaParams
from tests.unit.controller.scans import scan

JACKAL = Robot("r1", 2.0, 4.0, 0.22, 270.0, max_linear_accel_mps2=10.0, max_angular_accel_rps2=20.0)
BOX = ((0.254, -0.215), (0.254, 0.215), (-0.254, 0.215), (-0.254, -0.215))


def test_a_straight_or_gently_bending_path_is_faced_at_its_carrot() -> None:
    straight = tr.localise(np.array([[0.0, 0.0], [5.0, 0.0]]), 2.9, 0.1)
    assert straight is not None and straight.aim is None
    assert straight.facing == pytest.approx((2.9, 0.0))
    # a bend of 5 cm over 2 m: the line to the carrot passes 2.5 cm from it, within sight
    gentle = tr.localise(np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.05]]), 2.9, 0.1)
    assert gentle is not None and gentle.aim is None


def test_past_a_sharp_bend_the_robot_faces_along_what_it_can_see() -> None:
    # an L: 1 m ahead, then 2 m left; the carrot 2.5 m along, at (1, 1.5), 56 degrees left;
    # the line to it passes 0.83 m from the corner. In sight: the corner and 9 cm past it
    # (the 16th of the leg within 0.1 m of the corner: 1.5 / 16 = 0.094 m), so the robot
    # faces 5.4 degrees left, as far off as the carrot (1.80 m)
    local = tr.localise(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 2.0]]), 2.5, 0.1)
    assert local is not None and local.carrot == pytest.approx((1.0, 1.5))
    assert local.aim is not None
    assert math.degrees(math.atan2(local.aim[1], local.aim[0])) == pytest.approx(5.36, abs=0.01)
    assert math.hypot(*local.aim) == pytest.approx(math.hypot(1.0, 1.5))
    # sight 0: the carrot, as before
    off = tr.localise(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 2.0]]), 2.5, 0.0)
    assert off is not None and off.aim is None and off.facing == pytest.approx((1.0, 1.5))


@pytest.mark.parametrize("polygon", [None, BOX], ids=["disc", "box"])
def test_a_path_round_a_crate_is_followed_not_the_carrot_behind_it(polygon: object) -> None:
    # The Jackal standing, facing a crate 0.55 m ahead; the path goes round it on the
    # right (0.6 m right, 1.2 m on, back left) and the carrot, 2.9 m along, lies straight
    # ahead behind the crate. Facing the carrot, standing still scored best (no progress,
    # on the path, heading 0), and the robot stood until recovery; facing where the path
    # is seen to lead, it turns right onto it, moving
    crate = scan((-20.0, 45.0, 0.55))
    path = PlannedPath(
        7,
        "r1",
        10.0,
        1,
        "goal",
        3.0,
        0.0,
        (0.0, 0.0, 1.2, 1.2, 3.0),
        (0.0, -0.6, -0.6, 0.0, 0.0),
        3.0,
    )
    standing = Odometry(1, "r1", 10.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    shape = None if polygon is None else BOX
    before = choose(crate, standing, JACKAL, path, DwaParams.read({"dwa_sight_m": 0}), shape)
    assert before is not None and before.best is not None
    assert (before.window.v[before.best], before.window.w[before.best]) == (0.0, 0.0)
    now = choose(crate, standing, JACKAL, path, DwaParams(), shape)
    assert now is not None and now.best is not None
    assert now.window.v[now.best] > 0.2 and now.window.w[now.best] <= -1.5
    assert "speed 0.00" not in command_for(now, path).reason

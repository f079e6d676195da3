"""The robot's own trail as evidence of free space (common/trail.py), and the two that back up
on it: recovery (a lidar blind behind backs up only along it) and safety_stop (a blind
reverse on it passes), tick by tick."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.contract.records import LaserScan, Odometry, Robot
from common.footprint import Footprint
from common.trail import Trail
from services.controller.safety_stop import SafetyStop
from services.planner.recovery import BACK_UP, ROTATE, Machine, Observation, RecoveryParams
from services.planner.recovery_rule import retrace

BOX = ((0.254, -0.215), (0.254, 0.215), (-0.254, 0.215), (-0.254, -0.215))
FOOT = Footprint.of(0.22, BOX)
JACKAL = Robot(
    "r1", 2.0, 4.0, 0.22, 270.0, max_linear_accel_mps2=10.0, max_angular_accel_rps2=20.0,
    footprint_polygon=BOX,
)  # fmt: skip


def straight_in(metres: float = 1.2) -> Trail:
    """A trail driven straight along +x from the origin, a pose every 2 cm."""
    trail = Trail()
    for i in range(round(metres / 0.02) + 1):
        trail.note(0.05 * i, 0.02 * i, 0.0, 0.0)
    return trail


def curved_in(
    radius: float = 1.0, turned: float = 0.8, step: float = 0.01
) -> tuple[Trail, tuple[float, float, float]]:
    """A trail along a left-hand arc of ``radius`` from the origin (a pose every ``step``
    rad), and the pose at its end."""
    trail = Trail()
    steps = round(turned / step)
    for i in range(steps + 1):
        a = step * i
        trail.note(0.05 * i, radius * math.sin(a), radius * (1.0 - math.cos(a)), a)
    return trail, (radius * math.sin(turned), radius * (1.0 - math.cos(turned)), turned)


def test_backing_straight_out_along_a_straight_trail_is_covered_and_nothing_else() -> None:
    trail, end = straight_in(), (1.2, 0.0, 0.0)
    assert trail.covers(FOOT, end, -0.15, 0.0, 0.3)  # back the way it came
    assert not trail.covers(FOOT, end, 0.15, 0.0, 0.1)  # on ahead: never been there
    assert not trail.covers(FOOT, end, -0.15, -0.6, 0.3)  # back, swinging a corner out
    assert trail.covers(FOOT, end, -0.15, 0.0, 1.0)  # as far as it came in (1.2 m)...
    assert not trail.covers(FOOT, end, -0.15, 0.0, 1.3)  # ...and not past its first pose
    assert trail.retrace_turn(end, 0.2) == pytest.approx(0.0)
    assert not Trail().covers(FOOT, end, -0.15, 0.0, 0.1)  # no trail: nothing is known


def test_a_curved_trail_is_retraced_on_its_curvature_not_straight_back() -> None:
    # in along a 1 m radius arc (1 rad/m): the pose 0.2 m back is steered for at about
    # that curvature; backing on it stays within the outlines, straight back does not
    trail, end = curved_in()
    turn = trail.retrace_turn(end, 0.2)
    assert turn == pytest.approx(1.0, abs=0.01)
    assert trail.covers(FOOT, end, -0.15, -0.15 * turn, 0.3)
    assert not trail.covers(FOOT, end, -0.15, 0.0, 0.3)
    # poses 8 cm apart (odometry read every 0.1 s at 0.8 m/s): between two of them the
    # turning box's outlines leave notches at the corners, which it swept through; the
    # poses are filled in, so the same retrace is covered
    sparse, end = curved_in(step=0.08)
    assert sparse.covers(FOOT, end, -0.15, -0.15 * turn, 0.3)


def test_backing_up_adds_nothing_and_the_retrace_goes_on_from_where_the_robot_is() -> None:
    trail, end = curved_in()
    count = len(trail.poses)
    a = end[2] - 0.105  # 10.5 cm back along the arc it came in on
    back = (math.sin(a), 1.0 - math.cos(a), a)
    trail.note(5.0, *back)  # backing up: on the trail already
    assert len(trail.poses) == count
    # steered on from where the robot is, for the pose 0.2 m behind it on the same arc
    turn = trail.retrace_turn(back, 0.2)
    assert turn == pytest.approx(1.0, abs=0.01)
    assert trail.covers(FOOT, back, -0.15, -0.15 * turn, 0.3)
    # then forward again, turning off right: noted (it is going somewhere new)
    ahead = (back[0] + 0.05 * math.cos(back[2] - 0.3), back[1] + 0.05 * math.sin(back[2] - 0.3))
    trail.note(6.0, *ahead, back[2] - 0.3)
    assert len(trail.poses) == count + 1


def test_poses_are_kept_a_step_apart_and_for_a_while_only() -> None:
    trail = Trail()
    for i in range(10):  # standing still: one pose
        trail.note(0.1 * i, 0.0, 0.0, 0.0)
    assert len(trail.poses) == 1
    trail.note(1.0, 0.0, 0.0, 0.1)  # turned 5.7 degrees: kept
    trail.note(40.0, 1.0, 0.0, 0.1)  # 39 s later: the old poses are no evidence any more
    assert [p[0] for p in trail.poses] == [40.0]


def jackal_scan() -> LaserScan:
    """The Jackal's 270 degrees, nothing in range: blind behind."""
    ranges = np.full(720, np.inf, dtype=np.float32)
    return LaserScan(
        1, "r1", 10.0, math.radians(-135.0), math.radians(270.0 / 719), 0.1, 30.0, ranges
    )


def test_safety_stop_lets_a_blind_reverse_on_the_trail_pass_and_stops_any_other() -> None:
    backing = Odometry(1, "r1", 10.0, 1.2, 0.0, 0.0, -0.15, 0.0)
    stop = SafetyStop.decide(jackal_scan(), backing, JACKAL, {}, None)
    assert stop is not None and "blind" in stop.reason  # no trail: blind, as before
    assert SafetyStop.decide(jackal_scan(), backing, JACKAL, {}, straight_in()) is None
    swinging = Odometry(1, "r1", 10.0, 1.2, 0.0, 0.0, -0.15, -0.8)  # off the trail
    stop = SafetyStop.decide(jackal_scan(), swinging, JACKAL, {}, straight_in())
    assert stop is not None and "blind" in stop.reason
    disc = Robot("r1", 2.0, 4.0, 0.22, 270.0, max_linear_accel_mps2=10.0)
    assert SafetyStop.decide(jackal_scan(), backing, disc, {}, straight_in()) is not None


def test_recovery_backs_a_blind_box_along_its_trail_then_rotates_where_it_ends() -> None:
    p = RecoveryParams(stuck_s=2.0, back_up_m=0.3)
    trail, end = curved_in()
    turn = retrace(trail, FOOT, Odometry(1, "r1", 9.0, *end, 0.0, 0.0), 0.15)
    assert turn == pytest.approx(1.0, abs=0.01)
    m = Machine()
    goal = ("goal", 1)

    def seen(t: float, back: float | None, clear: bool = True) -> Observation:
        return Observation(t, end[0], end[1], end[2], goal, 5.0, 5.0, 0.22, clear, True,
                           None, 0.0, back)  # fmt: skip

    m.step(seen(0.0, None), p)
    a = m.step(seen(2.0, turn), p)  # stuck: backs up on the trail's curvature
    assert (m.state, a.linear) == (BACK_UP, -0.15)
    assert a.angular == pytest.approx(-0.15 * turn) and "along its trail" in a.reason
    # nothing of the trail behind (straight in, 1.2 m, from the robot's own pose at its
    # start): no back-up, rotate
    none = retrace(straight_in(), FOOT, Odometry(1, "r1", 9.0, 0.0, 0.0, 0.0, 0.0, 0.0), 0.15)
    assert none is None
    m2 = Machine()
    m2.step(seen(0.0, None), p)
    m2.step(seen(2.0, None, clear=False), p)
    assert m2.state == ROTATE


def test_a_robot_that_turned_as_it_crept_in_backs_out_on_that_bend() -> None:
    # 0.5 m straight along +x, then 8 cm creeping while turning 0.3 rad right (a box
    # easing into a pocket): the arc toward the pose 0.2 m back cuts across the bend and
    # straight back leaves it; the bend's own curvature (-3.75 rad/m) keeps to it
    trail = straight_in(0.5)
    x, y, yaw = 0.5, 0.0, 0.0
    for j in range(1, 9):
        yaw -= 0.3 / 8
        x, y = x + 0.01 * math.cos(yaw), y + 0.01 * math.sin(yaw)
        trail.note(3.0 + 0.1 * j, x, y, yaw)
    odom = Odometry(1, "r1", 4.0, x, y, yaw, 0.0, 0.0)
    pursuit = trail.retrace_turn((x, y, yaw), 0.2)
    assert pursuit is not None
    assert not trail.covers(FOOT, (x, y, yaw), -0.15, -0.15 * pursuit, 0.05)
    assert not trail.covers(FOOT, (x, y, yaw), -0.15, 0.0, 0.05)
    turn = retrace(trail, FOOT, odom, 0.15)
    assert turn == pytest.approx(-3.75, abs=0.01)


def test_the_boxes_closed_form_agrees_with_the_general_outline() -> None:
    # the same box with a fifth vertex in the middle of its front edge takes the general
    # outline distance; every verdict is the same as the rectangle's closed form
    general = Footprint.of(0.22, (BOX[0], (0.254, 0.0), *BOX[1:]))
    trail, end = curved_in(step=0.05)
    for turn in (-3.0, -1.0, 0.0, 1.0, 2.5):
        for distance in (0.03, 0.1, 0.3, 0.6):
            boxed = trail.covers(FOOT, end, -0.15, -0.15 * turn, distance)
            assert trail.covers(general, end, -0.15, -0.15 * turn, distance) == boxed

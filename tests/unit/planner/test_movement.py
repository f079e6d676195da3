"""Movement selection by angle (the thesis' selectMovement) and move_while_turning."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from common.planner_core.scenario import Movement
from services.planner import move_while_turning, turn_then_move
from services.planner.cadence import RECOMMEND_PERIOD_S, Said, due
from services.planner.tracking import Route, follow, heading_error, wrap_angle

MAX_V, MAX_W = 0.22, 2.84


def select(error: float, turning: bool = False) -> Movement:
    return turn_then_move.select_movement(error, 3.0, MAX_V, MAX_W, turning)


def select_turning(error: float, turn_rate: float = 0.0) -> Movement:
    return turn_then_move.select_movement(error, 3.0, MAX_V, MAX_W, True, turn_rate=turn_rate)


def test_goal_ahead_drives_forward() -> None:
    move = select(heading_error(0.0, 0.0, 0.0, (2.0, 0.05)))
    assert not move.turning
    assert move.linear == pytest.approx(MAX_V)
    assert abs(move.angular) < 0.1


def test_goal_to_the_left_turns_left() -> None:
    move = select(heading_error(0.0, 0.0, 0.0, (0.0, 2.0)))  # 90 degrees to the left
    assert move.turning and move.linear == 0.0 and move.angular > 0


def test_goal_to_the_right_turns_right() -> None:
    move = select(heading_error(0.0, 0.0, 0.0, (0.0, -2.0)))
    assert move.turning and move.linear == 0.0 and move.angular < 0


@pytest.mark.parametrize("yaw", [0.0, 1.0, -2.5, math.pi])
def test_goal_behind_turns_in_place(yaw: float) -> None:
    behind = (-2.0 * math.cos(yaw), -2.0 * math.sin(yaw))
    move = select(heading_error(0.0, 0.0, yaw, behind))
    assert move.turning and move.linear == 0.0 and move.angular != 0.0
    assert abs(move.angular) <= MAX_W


def test_turning_is_capped_and_never_stalls() -> None:
    # Far from the target heading: the turn-in-place cap (below the robot's maximum, which
    # a delayed loop would overshoot); near it, a smaller cap; never below the minimum.
    assert select(3.0).angular == pytest.approx(min(MAX_W, turn_then_move.MAX_TURN_RPS))
    assert select(-3.0).angular == pytest.approx(-min(MAX_W, turn_then_move.MAX_TURN_RPS))
    assert select(0.45).angular <= turn_then_move.FINE_TURN_RPS
    assert select(0.35).angular >= turn_then_move.MIN_TURN_RPS
    assert turn_then_move.select_movement(3.0, 3.0, MAX_V, 1.0).angular == pytest.approx(1.0)


def test_hysteresis_keeps_turning_until_well_aligned() -> None:
    assert not select(0.25).turning  # under the threshold, was driving: drive
    assert select(0.25, turning=True).turning  # was turning: finish the turn
    assert not select(0.1, turning=True).turning


def test_a_turn_still_under_way_is_anticipated() -> None:
    # Turning fast toward the target heading: the turn ends before the error is small, since
    # the robot keeps turning until the loop catches up...
    assert not select_turning(0.4, turn_rate=2.0).turning
    # ...and slows down first: the rate follows the anticipated error.
    assert 0 < select_turning(0.8, turn_rate=1.5).angular < select_turning(0.8).angular
    # Still turning toward it after the turn ended: no new turn in place.
    assert not turn_then_move.select_movement(0.35, 3.0, MAX_V, MAX_W, turn_rate=0.5).turning
    assert turn_then_move.select_movement(0.35, 3.0, MAX_V, MAX_W).turning
    # Sweeping past the target heading: stop turning in place, the correction brakes.
    move = select_turning(-0.1, turn_rate=1.0)
    assert not move.turning and move.angular < 0


@pytest.mark.parametrize("delay_s", [0.0, 0.1, 0.3, 0.5])
@pytest.mark.parametrize("target", [0.6, math.pi / 2, 3.0])
def test_turning_in_place_with_a_delayed_loop_does_not_oscillate(
    delay_s: float, target: float
) -> None:
    """Odometry at 30 Hz, commands reaching the wheels ``delay_s`` later (an accelerated sim
    on a busy machine), recommendations at the planner's cadence: the turn never reverses,
    overshoots little, and hands over to driving once, within a few seconds."""
    yaw, rate, turning, said = 0.0, 0.0, False, None
    pending: list[tuple[float, Movement]] = []
    reversals, switches, overshoot, drove_at = 0, 0, 0.0, None
    for step in range(30 * 6):
        t = step / 30
        move = turn_then_move.select_movement(
            wrap_angle(target - yaw), 3.0, MAX_V, MAX_W, turning, turn_rate=rate
        )
        if due(said, t, ("goal",), move):
            switches += move.turning != turning
            said, turning = Said(t, ("goal",), move), move.turning
            pending.append((t + delay_s, move))
        for _ in range(4):  # the wheels, at 120 Hz
            while pending and pending[0][0] <= t + 1e-9:
                applied = pending.pop(0)[1]
                reversals += applied.linear == 0.0 and applied.angular * rate < 0
                rate = applied.angular
                if applied.linear > 0 and drove_at is None:
                    drove_at = t
            yaw += rate / 120
            overshoot = max(overshoot, yaw - target)
    assert reversals == 0
    assert switches == 2  # into the turn, and out of it, once
    assert overshoot < 0.1
    assert drove_at is not None and drove_at < target / 1.2 + 1.5 + delay_s
    assert abs(wrap_angle(target - yaw)) < 0.05


def test_recommendations_go_out_on_change_or_at_the_cadence() -> None:
    drive = Movement(0.22, 0.05, False)
    said = Said(10.0, ("goal", "1"), drive)
    assert due(None, 10.0, ("goal", "1"), drive)  # the first
    assert not due(said, 10.03, ("goal", "1"), drive)  # nothing new
    assert not due(said, 10.06, ("goal", "1"), Movement(0.22, 0.09, False))  # a small change
    assert due(said, 10.0 + RECOMMEND_PERIOD_S, ("goal", "1"), drive)  # the cadence
    assert due(said, 10.03, ("goal", "2"), drive)  # a new target
    assert due(said, 10.03, ("goal", "1"), Movement(0.22, 0.3, False))  # steering harder
    assert due(said, 10.03, ("goal", "1"), Movement(0.15, 0.05, False))  # slowing down
    assert due(said, 10.03, ("goal", "1"), Movement(0.0, 0.5, True))  # turning in place
    assert due(said, 5.0, ("goal", "1"), drive)  # sim time went back


def test_driving_slows_near_the_target() -> None:
    near = turn_then_move.select_movement(0.0, 0.1, MAX_V, MAX_W)
    far = turn_then_move.select_movement(0.0, 3.0, MAX_V, MAX_W)
    assert 0 < near.linear < far.linear == pytest.approx(MAX_V)


@given(st.floats(-math.pi, math.pi), st.floats(0.0, 20.0))
def test_move_while_turning_never_drives_backward(error: float, remaining: float) -> None:
    move = move_while_turning.select_movement(error, remaining, MAX_V, MAX_W)
    assert 0.0 <= move.linear <= MAX_V
    assert abs(move.angular) <= MAX_W
    if abs(error) > 1e-6:
        assert math.copysign(1.0, move.angular) == math.copysign(1.0, error)


def test_move_while_turning_turns_on_the_spot_for_a_goal_behind() -> None:
    move = move_while_turning.select_movement(math.pi * 0.9, 2.0, MAX_V, MAX_W)
    assert move.linear == 0.0 and move.angular > 0
    ahead = move_while_turning.select_movement(0.2, 2.0, MAX_V, MAX_W)
    assert ahead.linear > 0.2 and ahead.angular > 0


def test_wrap_angle() -> None:
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap_angle(-math.pi) == pytest.approx(math.pi)


def test_the_follower_steers_along_the_segment_and_moves_on_at_a_vertex() -> None:
    route = Route.of(("goal", "1"), None, [(0.0, 0.0), (2.0, 0.0), (2.0, 2.0)], planned=True)
    progress = follow(route, 0.5, 0.1)
    assert progress.waypoint == 1 and progress.waypoints == 2
    assert progress.lookahead == pytest.approx((0.85, 0.0))
    assert progress.deviation_m == pytest.approx(0.1)
    assert progress.remaining_m == pytest.approx(0.1 + 1.5 + 2.0)
    near_corner = follow(route, 1.8, 0.0)
    assert near_corner.lookahead == pytest.approx((2.0, 0.0))  # never cuts the corner
    past = follow(route, 1.95, 0.05)
    assert past.waypoint == 2 and past.lookahead[1] > 0.0
    # progress is monotone: back near the start, the follower stays on the second segment
    assert follow(route, 0.2, 0.0).waypoint == 2

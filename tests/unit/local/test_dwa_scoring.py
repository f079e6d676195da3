"""The dwa local controller's scoring, step by step: the window, the arcs, admissibility,
each score term of a small trajectory set with its value written beside it, then
decisions tick by tick as the world in front of the robot changes."""

from __future__ import annotations

import math

import numpy as np
import pytest

import pnav_local.trajectories as tr
from common.contract.planned_path import PlannedPath
from common.contract.records import Odometry, Robot
from pnav_local.clearance import Footprint
from pnav_local.dwa import choose, command_for, stopping_speed
from pnav_local.dwa_params import DwaParams
from tests.unit.controller.scans import BURGER, scan

JACKAL = Robot("r1", 2.0, 4.0, 0.22, 270.0, max_linear_accel_mps2=10.0, max_angular_accel_rps2=20.0)


def straight_path(length: float = 3.0) -> PlannedPath:
    return PlannedPath(7, "r1", 10.0, 1, "goal", length, 0.0, (0.0, length), (0.0, 0.0), length)


def odom(
    v: float = 0.0, w: float = 0.0, x: float = 0.0, y: float = 0.0, yaw: float = 0.0
) -> Odometry:
    return Odometry(1, "r1", 10.0, x, y, yaw, v, w)


def test_the_window_is_what_the_acceleration_reaches_within_the_limits() -> None:
    # Burger at 0.1 m/s: +-2.5 m/s^2 x 0.3 s = +-0.75 m/s, cut to [0, 0.22] (forward only);
    # +-3.2 rad/s^2 x 0.3 s = +-0.96 rad/s around 0
    win = tr.window(0.1, 0.0, max_v=0.22, max_w=2.84, accel_v=2.5, accel_w=3.2, dt=0.3,
                    v_samples=3, w_samples=3)  # fmt: skip
    assert sorted(set(win.v.tolist())) == pytest.approx([0.0, 0.11, 0.22])
    assert sorted(set(win.w.tolist())) == pytest.approx([-0.96, 0.0, 0.96])
    assert len(win.v) == 9
    # Jackal at 2 m/s, turning 3.9 rad/s, 0.05 s window: 1.5..2.0 m/s, 2.9..4.0 rad/s, and
    # w = 0 is not reachable so not added
    win = tr.window(2.0, 3.9, max_v=2.0, max_w=4.0, accel_v=10.0, accel_w=20.0, dt=0.05,
                    v_samples=2, w_samples=2)  # fmt: skip
    assert sorted(set(win.v.tolist())) == pytest.approx([1.5, 2.0])
    assert sorted(set(win.w.tolist())) == pytest.approx([2.9, 4.0])
    # a cap (the path's end is near) lowers the top speed, never below 0
    win = tr.window(0.2, 0.0, max_v=0.22, max_w=2.84, accel_v=2.5, accel_w=3.2, dt=0.3,
                    v_samples=2, w_samples=1, v_cap=0.05)  # fmt: skip
    assert sorted(set(win.v.tolist())) == pytest.approx([0.0, 0.05])


def test_arcs_are_exact_for_straight_lines_and_turns() -> None:
    x, y, yaw = tr.arcs(
        np.array([0.2, 0.2, 0.0]), np.array([0.0, math.pi / 2, 1.0]), np.array([1.0])
    )
    assert (x[0, 0], y[0, 0], yaw[0, 0]) == pytest.approx((0.2, 0.0, 0.0))
    # a quarter turn at radius v/w = 0.4/pi: ends 0.127 m ahead and 0.127 m left, facing left
    r = 0.2 / (math.pi / 2)
    assert (x[1, 0], y[1, 0], yaw[1, 0]) == pytest.approx((r, r, math.pi / 2))
    assert (x[2, 0], y[2, 0], yaw[2, 0]) == pytest.approx((0.0, 0.0, 1.0))  # in place


def test_a_small_trajectory_set_scores_term_by_term() -> None:
    # four trajectories over a 1 s horizon (one step), the carrot 1 m ahead on the path,
    # nothing in sight, Burger-like top speed 0.2 m/s; default weights
    # (progress 1.0, path 0.6, heading 0.4, clearance 0.3, speed 0.3)
    win = tr.Window(np.array([0.0, 0.2, 0.2, 0.2]), np.array([0.0, 0.0, 0.5, -0.5]))
    poses = tr.rollout(win, (0.0, 0.0, 0.0), 1.0, 1)
    gaps = tr.distances(poses[0], poses[1], np.zeros((0, 2)))
    local = tr.Local(np.array([[0.0, 0.0], [1.0, 0.0]]), (1.0, 0.0), 3.0)
    s = tr.score(win, poses, gaps - 0.105, local, start=(0.0, 0.0, 0.0), max_v=0.2,
                 horizon_s=1.0, clearance_cap_m=0.5, weights=tr.Weights())  # fmt: skip
    # stand still: no progress, on the path, facing the carrot, no speed, and so no
    # clearance either (it counts times the speed share: standing never wins on room alone)
    assert (s.progress[0], s.path[0], s.heading[0], s.clearance[0], s.speed[0]) == (0, 0, 0, 0, 0)
    assert s.total[0] == pytest.approx(0.0)
    # straight on at top speed: 0.2 of the 0.2 m the horizon allows nearer the carrot
    assert (s.progress[1], s.path[1], s.heading[1], s.speed[1]) == pytest.approx((1, 0, 0, 1))
    assert s.total[1] == pytest.approx(1.6)
    # curving left at 0.5 rad/s: ends at (0.1918, 0.0490) facing 0.5 rad, 0.8097 m from the
    # carrot (progress 0.9515), 0.049 m off the path (0.2449 of 0.2), 0.5605 rad off the
    # carrot's bearing (0.1784 of pi)
    assert s.progress[2] == pytest.approx(0.9515, abs=1e-4)
    assert s.path[2] == pytest.approx(0.2449, abs=1e-4)
    assert s.heading[2] == pytest.approx(0.1784, abs=1e-4)
    assert s.total[2] == pytest.approx(0.9515 - 0.6 * 0.2449 - 0.4 * 0.1784 + 0.6, abs=1e-3)
    # curving right scores the same (mirror image): the straight one wins
    assert s.total[3] == pytest.approx(s.total[2])
    assert int(np.argmax(s.total)) == 1


def test_admissible_keeps_the_margin_except_for_a_brake_that_stops_in_time() -> None:
    # obstacle 1 m ahead; footprint 0.2 + margin 0.05: a pose within 0.25 m of it is a hit
    win = tr.Window(np.array([0.0, 0.5, 1.0, 1.0]), np.array([0.0, 0.0, 0.0, 3.0]))
    poses = tr.rollout(win, (0.0, 0.0, 0.0), 1.0, 10)
    # gaps beyond the footprint: centre distances less the radius
    gaps = tr.distances(poses[0], poses[1], np.array([[1.0, 0.0]])) - 0.2
    ok = tr.admissible(win, gaps, 1.0 - 0.2, margin_m=0.05, accel_v=2.0,
                       delay_s=0.1, horizon_s=1.0)  # fmt: skip
    # standing: fine; 0.5 m/s: ends 0.5 m short, fine; 1 m/s straight: its 1 m ends in
    # it; 1 m/s turning hard (radius 0.33 m) stays clear
    assert ok.tolist() == [True, True, False, True]
    # a robot already inside the margin (0.2 m from a wall) may still turn in place
    win = tr.Window(np.array([0.0, 0.3]), np.array([1.0, 0.0]))
    poses = tr.rollout(win, (0.0, 0.0, 0.0), 1.0, 10)
    gaps = tr.distances(poses[0], poses[1], np.array([[0.2, 0.0]])) - 0.105
    ok = tr.admissible(win, gaps, 0.2 - 0.105, margin_m=0.05, accel_v=2.5,
                       delay_s=0.1, horizon_s=1.0)  # fmt: skip
    assert ok.tolist() == [True, False]


def test_the_path_is_localised_from_the_robots_projection_with_a_carrot_ahead() -> None:
    # an L-shaped path: 1 m along x, then 2 m up; the robot at (0.5, 0.1)'s frame = shift
    path = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 2.0]]) - [0.5, 0.1]
    local = tr.localise(path, 1.0)
    assert local is not None
    assert local.remaining_m == pytest.approx(2.5)  # 0.5 m to the corner, 2 m up
    assert local.carrot == pytest.approx((0.5, 0.4))  # 0.5 m past the corner: (1.0, 0.5)
    assert local.points.ravel().tolist() == pytest.approx([0.0, -0.1, 0.5, -0.1, 0.5, 0.4])


def test_decisions_tick_by_tick_as_the_world_ahead_changes() -> None:
    p, path = DwaParams(), straight_path()
    # tick 1: nothing in sight, standing: full Burger speed, straight
    c = choose(scan(), odom(), BURGER, path, p)
    assert c is not None and c.best is not None
    assert (c.window.v[c.best], c.window.w[c.best]) == pytest.approx((0.22, 0.0))
    # tick 2: something on the path 0.35 m ahead (0 to +10 deg): the path runs into it
    # (the planner has not re-planned yet). The Burger's motors reach any turn rate within
    # the window (31.25 rad/s^2), so the 17 default samples are 0.355 rad/s apart; with the
    # path weighing 0.2 x as much while it is blocked and the heading judged along the whole
    # arc, rounding it on its free side, right, at full speed wins: w = -1.065 rad/s
    c = choose(scan((0.0, 10.0, 0.35)), odom(0.22), BURGER, path, p)
    assert c is not None and c.best is not None and c.blocked
    assert (c.window.v[c.best], c.window.w[c.best]) == pytest.approx((0.22, -1.065))
    # with 21 samples (0.284 rad/s apart) the rounding is tighter: w = -0.852 rad/s
    fine = DwaParams.read({"dwa_angular_samples": 21})
    c = choose(scan((0.0, 10.0, 0.35)), odom(0.22), BURGER, path, fine)
    assert c is not None and c.best is not None
    assert (c.window.v[c.best], c.window.w[c.best]) == pytest.approx((0.22, -0.852))
    # tick 2b: the path turns left 0.3 m ahead: it curves left, still driving
    bend = PlannedPath(8, "r1", 10.0, 1, "goal", 0.3, 2.0, (0.0, 0.3, 0.3), (0.0, 0.0, 2.0), 2.3)
    c = choose(scan(), odom(0.22), BURGER, bend, p)
    assert c is not None and c.best is not None
    assert c.window.v[c.best] > 0 and c.window.w[c.best] > 0
    # tick 3: a wall across everything ahead 0.15 m away, inside footprint + margin
    # (0.155 m): any forward motion brings it nearer: none at all
    c = choose(scan((-90.0, 90.0, 0.15)), odom(0.05), BURGER, path, p)
    assert c is not None and c.best is not None and c.window.v[c.best] == 0.0
    # tick 4: facing away from the path (yaw pi): it turns round at the full turn rate
    # (2.84 rad/s, reachable within the window), on an arc of radius v / w < 0.08 m
    c = choose(scan(), odom(yaw=math.pi), BURGER, path, p)
    assert c is not None and c.best is not None
    assert abs(c.window.w[c.best]) == pytest.approx(2.84)
    assert c.window.v[c.best] / abs(c.window.w[c.best]) < 0.08
    # tick 5: 0.1 m from the path's end at 0.2 m/s: the end caps the speed
    # (sqrt(2 x 2.5 x 0.1) x 0.8 = 0.566 m/s, no cap for the Burger), but the carrot is
    # the end: no trajectory goes past it for long
    c = choose(scan(), odom(0.2, x=2.9), BURGER, path, p)
    assert c is not None and c.best is not None
    assert c.window.v[c.best] * p.horizon_s < 0.1 + 0.1


def test_the_jackal_runs_at_its_own_speed_and_brakes_with_its_own_acceleration() -> None:
    p, path = DwaParams(), straight_path(10.0)
    c = choose(scan(), odom(2.0), JACKAL, path, p)
    assert c is not None and c.best is not None and c.window.v[c.best] == pytest.approx(2.0)
    # 0.5 m before the end: v <= sqrt(2 x 10 x 0.5) x 0.8 = 2.53: still full speed...
    c = choose(scan(), odom(2.0, x=9.5), JACKAL, path, p)
    assert c is not None and c.v_cap == pytest.approx(math.sqrt(10.0) * 0.8)
    # ...at 0.05 m: v <= sqrt(2 x 10 x 0.05) x 0.8 = 0.8 m/s
    c = choose(scan(), odom(1.0, x=9.95), JACKAL, path, p)
    assert c is not None and c.best is not None and c.window.v[c.best] <= 0.8 + 1e-9


def test_the_command_names_the_path_and_every_term() -> None:
    path = straight_path()
    c = choose(scan(), odom(), BURGER, path, DwaParams())
    assert c is not None
    cmd = command_for(c, path)
    assert cmd.inputs == {"planned_path": 7}
    assert cmd.reason.startswith("dwa: best of 153/153 admissible trajectories: progress +")
    boxed = choose(scan((-180.0, 180.0, 0.12)), odom(0.2), BURGER, path, DwaParams())
    assert boxed is not None
    if boxed.best is None:
        assert command_for(boxed, path).reason.endswith("is admissible: brake")


def test_params_out_of_range_take_their_defaults() -> None:
    p = DwaParams.read({"dwa_horizon_s": -1, "dwa_linear_samples": 5, "dwa_speed_weight": "x"})
    assert p.horizon_s == DwaParams().horizon_s and p.linear_samples == 5
    assert p.weights.speed == DwaParams().weights.speed


@pytest.mark.parametrize(
    ("gap", "lookahead", "accel"), [(1.0, 0.2, 10.0), (0.3, 0.2, 2.5), (2.0, 0.0, 2.5)]
)
def test_the_speed_cap_stops_within_the_gap_after_safety_stops_lookahead(
    gap: float, lookahead: float, accel: float
) -> None:
    v = stopping_speed(gap, lookahead, accel)
    assert v * lookahead + v * v / (2 * accel) == pytest.approx(gap)  # safety_stop's reach
    assert stopping_speed(0.0, lookahead, accel) == 0.0


def test_a_slow_arc_must_stay_clear_for_the_minimum_travel_not_only_the_horizon() -> None:
    # 0.05 m/s straight at a crate 0.3 m ahead: clear for the 1.2 s horizon (6 cm), so the
    # horizon alone admits it, and the robot would creep ever slower toward it; followed on
    # for 0.4 m it meets the crate: refused. Turning tight at that speed (radius 2.5 cm,
    # half a turn) and turning in place stay clear.
    win = tr.Window(np.array([0.05, 0.05, 0.0]), np.array([0.0, 2.0, 1.0]))
    crate = np.array([[0.3, 0.0]])
    poses = tr.rollout(win, (0.0, 0.0, 0.0), 1.2, 10)
    gaps = tr.distances(poses[0], poses[1], crate) - 0.105
    ok = tr.admissible(win, gaps, 0.3 - 0.105, margin_m=0.05, accel_v=2.5,
                       delay_s=0.1, horizon_s=1.2)  # fmt: skip
    assert ok.tolist() == [True, True, True]
    disc = Footprint(0.105)
    clear = tr.clear_for(win, (0.0, 0.0, 0.0), crate, 0.4, 1.2, 10, 0.05, disc)
    assert clear.tolist() == [False, True, True]
    # a fast arc covers 0.4 m within the horizon: admissible() judged it, nothing more
    fast = tr.Window(np.array([0.5]), np.array([0.0]))
    assert tr.clear_for(fast, (0.0, 0.0, 0.0), crate, 0.4, 1.2, 10, 0.05, disc).tolist() == [True]


def test_the_turn_rate_that_faces_the_carrot_is_sampled() -> None:
    # the Burger 0.15 rad left of its path: 17 samples 0.355 rad/s apart would overshoot
    # the carrot (0.8 m ahead); the window also holds -0.15 / 1.2 = -0.125 rad/s, and with
    # nothing in the way it drives on at full speed with that turn
    win = tr.window(0.0, 0.0, max_v=0.22, max_w=2.84, accel_v=2.5, accel_w=31.25, dt=0.3,
                    v_samples=9, w_samples=17, extra_w=-0.125)  # fmt: skip
    assert np.any(np.isclose(win.w, -0.125))
    c = choose(scan(), odom(yaw=0.15), BURGER, straight_path(), DwaParams())
    assert c is not None and c.best is not None
    assert (c.window.v[c.best], c.window.w[c.best]) == pytest.approx((0.22, -0.125))


def test_the_heading_counts_along_the_whole_arc() -> None:
    # two arcs ending at the same pose facing the carrot: one straight, one swinging 90
    # degrees off and back (poses given by hand): the swing scores a worse heading
    local = tr.localise(np.array([[0.0, 0.0], [5.0, 0.0]]), 3.0)
    assert local is not None
    xs = np.array([[0.5, 1.0], [0.5, 1.0]])
    ys = np.zeros((2, 2))
    yaws = np.array([[0.0, 0.0], [math.pi / 2, 0.0]])
    win = tr.Window(np.array([1.0, 1.0]), np.array([0.0, 0.0]))
    s = tr.score(win, (xs, ys, yaws), np.full((2, 2), 9.0), local, start=(0.0, 0.0, 0.0),
                 max_v=1.0, horizon_s=1.0, clearance_cap_m=0.5,
                 weights=tr.Weights())  # fmt: skip
    assert s.heading[0] == pytest.approx(0.0)
    assert s.heading[1] == pytest.approx(0.25)  # 90 degrees (0.5 of pi) for half the arc


def test_the_minimum_travel_counts_at_the_robots_top_speed() -> None:
    # a crate 0.35 m ahead of a robot crawling at 0.05 m/s, facing its path: the Jackal
    # (0.2 s x 2 m/s = 0.4 m) may not creep on straight toward it; the Burger (0.044 m,
    # less than its own horizon covers) is judged on the horizon alone and may
    crate = scan((-3.0, 3.0, 0.35 + 0.22))
    jackal = choose(crate, odom(0.05), JACKAL, straight_path(), DwaParams())
    assert jackal is not None
    win = jackal.window
    slow = (win.w == 0.0) & (win.v > 0.0) & (win.v * 1.2 < 0.4)
    assert slow.any() and not jackal.ok[slow].any()
    horizon_only = choose(
        crate, odom(0.05), JACKAL, straight_path(), DwaParams.read({"dwa_min_travel_s": 0})
    )
    assert horizon_only is not None and horizon_only.ok[slow].any()
    burger = choose(
        scan((-3.0, 3.0, 0.35 + 0.105)), odom(0.05), BURGER, straight_path(), DwaParams()
    )
    assert burger is not None
    straight = (burger.window.w == 0.0) & (burger.window.v > 0.0) & (burger.window.v < 0.1)
    assert straight.any() and burger.ok[straight].all()

"""dwa's two-segment roll-outs for a footprint polygon: straight on for ``dwa_bend_s``, then
a turn. One arc for the whole horizon cannot say "straight through this gap, then turn
where the path turns"; a box leaving a gap whose path turns just past it took an arc into
the pocket beside it, or stood (barn_hard_001). And the squeeze: a box that can move nowhere
with the margin is admitted with ``dwa_squeeze_margin_m``."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest

import pnav_local.trajectories as tr
from common.contract.planned_path import PlannedPath
from common.contract.records import LaserScan, Odometry
from pnav_local.dwa import choose, command_for, obstacles
from pnav_local.dwa_params import POSE_BUDGET, DwaParams
from tests.unit.local import dwa_reference
from tests.unit.local.test_dwa_reference import BOX, JACKAL

BEAMS, FOV = 720, math.radians(270.0)
Boxes = tuple[tuple[float, float, float, float], ...]  # x0, x1, y0, y1


def scan_of(boxes: Boxes, yaw: float = 0.0) -> LaserScan:
    """What a 720-beam 270-degree lidar at the origin facing ``yaw`` sees of these boxes."""
    angles = -FOV / 2 + FOV / (BEAMS - 1) * np.arange(BEAMS)
    dx, dy = np.cos(angles + yaw), np.sin(angles + yaw)
    ranges = np.full(BEAMS, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for x0, x1, y0, y1 in boxes:
            near = np.maximum(np.minimum(x0 / dx, x1 / dx), np.minimum(y0 / dy, y1 / dy))
            far = np.minimum(np.maximum(x0 / dx, x1 / dx), np.maximum(y0 / dy, y1 / dy))
            ranges = np.where((far >= near) & (near > 0), np.minimum(ranges, near), ranges)
    return LaserScan(1, "r1", 1.0, -FOV / 2, FOV / (BEAMS - 1), 0.05, 10.0, ranges.astype("f4"))


def path_of(points: list[tuple[float, float]]) -> PlannedPath:
    xs, ys = tuple(p[0] for p in points), tuple(p[1] for p in points)
    length = sum(math.dist(a, b) for a, b in itertools.pairwise(points))
    return PlannedPath(1, "r1", 1.0, 1, "goal", xs[-1], ys[-1], xs, ys, length)


def test_a_bend_holds_its_first_arc_then_turns_from_where_it_ended() -> None:
    # 1 m/s straight for 0.4 s, then a quarter turn left over the 0.8 s left
    w2 = (math.pi / 2) / 0.8
    one, straight = np.array([1.0]), np.array([0.0])
    x, y, yaw = tr.bends(one, straight, one, np.array([w2]), 0.4, np.array([0.2, 0.4, 1.2]))
    r = 1.0 / w2
    assert x[0].tolist() == pytest.approx([0.2, 0.4, 0.4 + r])
    assert y[0].tolist() == pytest.approx([0.0, 0.0, r])
    assert yaw[0].tolist() == pytest.approx([0.0, 0.0, math.pi / 2])
    # a turning first arc: the second starts at its end, at its heading
    x, y, yaw = tr.bends(one, one, one, straight, 0.4, np.array([1.2]))
    x1, y1 = math.sin(0.4), 1.0 - math.cos(0.4)
    assert (x[0, 0], y[0, 0]) == pytest.approx((x1 + 0.8 * math.cos(0.4), y1 + 0.8 * math.sin(0.4)))
    assert yaw[0, 0] == pytest.approx(0.4)
    # a turn in place, then straight on at another speed: it moves only after the turn
    x, y, yaw = tr.bends(straight, np.array([0.5]), np.array([0.5]), straight, 0.4,
                         np.array([0.4, 1.2]))  # fmt: skip
    assert x[0].tolist() == pytest.approx([0.0, 0.4 * math.cos(0.2)])
    assert y[0].tolist() == pytest.approx([0.0, 0.4 * math.sin(0.2)])


def test_the_window_gains_straight_then_turn_at_each_fast_enough_speed() -> None:
    win = tr.window(0.5, 0.0, max_v=2.0, max_w=4.0, accel_v=10.0, accel_w=20.0, dt=0.3,
                    v_samples=9, w_samples=17)  # fmt: skip
    bent = tr.with_bends(win, bend_s=0.4, max_v=2.0, max_w=4.0, accel_v=10.0, accel_w=20.0,
                         turns=8, min_v=0.4, aim=(3.0, 3.0), horizon_s=1.2)  # fmt: skip
    n = win.arcs
    assert bent.arcs == n == len(win.v) and bent.then_w is not None and bent.then_v is not None
    # the arcs first, unchanged
    assert bent.v[:n].tolist() == win.v.tolist() and bent.w[:n].tolist() == win.w.tolist()
    v, w, then_v, then_w = bent.v[n:], bent.w[n:], bent.then_v, bent.then_w
    # turn a little at the window's slowest speed, then straight on at 0.6 m/s (what covers
    # 0.4 m / 1.2 s x 1.2 s in the 0.8 s left): squaring up to a gap
    squaring = w != 0.0
    assert sorted(w[squaring].tolist()) == [-1.0, -0.5, -0.25, 0.25, 0.5, 1.0]
    assert (v[squaring] == win.v.min()).all() and (then_w[squaring] == 0.0).all()
    assert then_v[squaring].tolist() == pytest.approx([0.6] * 6)
    # straight on, then turn, at the same speed
    assert (then_v[~squaring] == v[~squaring]).all()
    speeds = sorted(set(v[~squaring].tolist()))
    assert speeds == [s for s in sorted(set(win.v.tolist())) if s >= 0.4]
    for speed in speeds:
        rates = sorted(then_w[~squaring & (v == speed)].tolist())
        # +-1..4 rad/s, and the rate facing the aim from where the straight ends: left
        fixed = [-4.0, -3.0, -2.0, -1.0, 1.0, 2.0, 3.0, 4.0]
        extra = [r for r in rates if r not in fixed]
        assert [r for r in rates if r in fixed] == fixed and len(extra) == 1 and extra[0] > 0
    # none asked, or a horizon no longer than the first segment: the window as it was
    limits = {"max_v": 2.0, "max_w": 4.0, "accel_v": 10.0, "accel_w": 20.0}
    assert tr.with_bends(win, bend_s=0.4, turns=0, min_v=0.0, **limits) is win
    assert tr.with_bends(win, bend_s=1.2, turns=8, min_v=0.0, horizon_s=1.2, **limits) is win


# posts 0.6 m apart (the Jackal's box 0.43 m wide: 8.5 cm each side) 0.5 m ahead; past them
# a wall across the way straight on, open to the left, and the path turning left past the
# posts: the box must go through square, then turn
POSTS: Boxes = ((0.5, 0.65, 0.30, 0.6), (0.5, 0.65, -0.6, -0.30), (1.6, 1.8, -2.0, 0.5))
LEFT_PAST_THE_GAP = [(0.0, 0.0), (0.95, 0.0), (0.95, 3.0)]


def test_only_straight_on_then_turn_clears_the_gap_at_speed() -> None:
    scan, path = scan_of(POSTS), path_of(LEFT_PAST_THE_GAP)
    odom = Odometry(1, "r1", 1.0, 0.0, 0.0, 0.0, 1.0, 0.0)  # driving at 1 m/s
    p = DwaParams.read({})
    choice = choose(scan, odom, JACKAL, path, p, BOX)
    assert choice is not None and choice.best is not None
    win, best = choice.window, choice.best
    assert win.then_w is not None
    # the winner: straight on at speed through the posts, then a turn left
    assert best >= win.arcs and win.w[best] == 0.0 and win.then_w[best - win.arcs] > 0.0
    assert win.v[best] >= 1.5
    # no single arc at that speed is admissible: each meets a post or the wall
    single = np.flatnonzero(np.isclose(win.v[: win.arcs], win.v[best]))
    assert len(single) > 0 and not choice.ok[single].any()
    command = command_for(choice, path)
    assert (command.linear, command.angular) == (win.v[best], 0.0)
    assert f"(this for 0.40 s, then {win.v[best]:.2f} m/s, +" in command.reason
    # the plain reference decides the same
    plain = dwa_reference.choose(scan, odom, JACKAL, path, p, BOX)
    assert plain is not None and plain.best == best and plain.ok.tolist() == choice.ok.tolist()
    # without them (dwa_bend_turns 0): a slow straight arc, not what leaves the gap at speed
    without = choose(scan, odom, JACKAL, path, DwaParams.read({"dwa_bend_turns": 0}), BOX)
    assert without is not None and without.best is not None
    assert without.window.then_w is None
    assert without.window.v[without.best] <= 0.75


def test_a_disc_gets_no_bends() -> None:
    scan, path = scan_of(POSTS), path_of(LEFT_PAST_THE_GAP)
    odom = Odometry(1, "r1", 1.0, 0.0, 0.0, 0.0, 1.0, 0.0)
    choice = choose(scan, odom, JACKAL, path, DwaParams.read({}), None)
    assert choice is not None and choice.window.then_w is None


# a corridor 6 cm wider than the box each side, narrowing 0.4 m ahead to 3.5 cm each side
SQUEEZE: Boxes = (
    (-1.0, 0.4, 0.275, 0.5),
    (-1.0, 0.4, -0.5, -0.275),
    (0.4, 1.2, 0.25, 0.5),
    (0.4, 1.2, -0.5, -0.25),
)


def test_a_box_that_moves_nowhere_with_the_margin_squeezes_through() -> None:
    scan, path = scan_of(SQUEEZE), path_of([(0.0, 0.0), (3.0, 0.0)])
    odom = Odometry(1, "r1", 1.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    # nothing moving keeps the 5 cm margin past the narrowing; with 2 cm the box goes on
    strict = choose(scan, odom, JACKAL, path, DwaParams.read({"dwa_squeeze_margin_m": 0}), BOX)
    assert strict is not None and strict.best is not None
    assert not strict.ok[strict.window.v > 0].any() and strict.window.v[strict.best] == 0.0
    squeezed = choose(scan, odom, JACKAL, path, DwaParams.read({}), BOX)
    assert squeezed is not None and squeezed.best is not None and squeezed.squeezed
    assert squeezed.window.v[squeezed.best] > 0.0
    assert "(squeezing: nothing moves with the margin)" in command_for(squeezed, path).reason
    plain = dwa_reference.choose(scan, odom, JACKAL, path, DwaParams.read({}), BOX)
    assert plain is not None and plain.best == squeezed.best and plain.squeezed
    # the disc is never squeezed (its margin is the planner's own)
    disc = choose(scan, odom, JACKAL, path, DwaParams.read({}), None)
    assert disc is not None and not disc.squeezed


def test_the_box_with_the_heaviest_params_stays_within_the_pose_budget() -> None:
    worst = {"dwa_steps": 50, "dwa_linear_samples": 50, "dwa_angular_samples": 100,
             "dwa_horizon_s": 10, "dwa_bend_turns": 16}  # fmt: skip
    p = DwaParams.read(worst)
    scan, path = scan_of(POSTS), path_of(LEFT_PAST_THE_GAP)
    for v in (0.0, 1.0, 2.0):
        odom = Odometry(1, "r1", 1.0, 0.0, 0.0, 0.0, v, 0.0)
        choice = choose(scan, odom, JACKAL, path, p, BOX)
        assert choice is not None
        assert len(choice.window.v) * p.steps <= POSE_BUDGET
        assert choice.window.then_w is not None and len(choice.window.then_w) > 0


def test_a_box_squares_up_to_a_gap_it_passes_only_square() -> None:
    # posts 0.57 m apart (7 cm each side of the box square on), the robot and its path 11
    # degrees off the gap's axis: every arc forward meets a post, a turn in place scores no
    # progress; "turn 0.2 rad, then straight on" is what passes
    yaw = math.radians(11.0)
    posts: Boxes = ((0.45, 0.75, 0.285, 0.585), (0.45, 0.75, -0.585, -0.285))
    scan = scan_of(posts, yaw)
    path = path_of([(0.0, 0.0), (3.0 * math.cos(yaw), 3.0 * math.sin(yaw))])
    odom = Odometry(1, "r1", 1.0, 0.0, 0.0, yaw, 0.0, 0.0)
    p = DwaParams.read({})
    choice = choose(scan, odom, JACKAL, path, p, BOX)
    assert choice is not None and choice.best is not None
    win, best = choice.window, choice.best
    assert win.then_w is not None and win.then_v is not None and best >= win.arcs
    assert (win.v[best], win.w[best]) == (0.0, -0.5)
    assert (win.then_v[best - win.arcs], win.then_w[best - win.arcs]) == pytest.approx((0.5, 0.0))
    plain = dwa_reference.choose(scan, odom, JACKAL, path, p, BOX)
    assert plain is not None and plain.best == best
    # without the two-segment roll-outs it stands
    without = choose(scan, odom, JACKAL, path, DwaParams.read({"dwa_bend_turns": 0}), BOX)
    assert without is not None and without.best is not None
    assert (without.window.v[without.best], without.window.w[without.best]) == (0.0, 0.0)


def recorded_tick() -> tuple[LaserScan, Odometry, PlannedPath]:
    """dynabarn_hard_000's tick at 1.46 s (GOTO_DODGE, the Jackal), as the merged tree's run
    recorded it: a mover 1.1 m ahead to the left crossing the way, the field open."""
    doc = json.loads(TICK.read_text())
    s, o, p = doc["scan"], doc["odom"], doc["path"]
    ranges = np.asarray(s["ranges_mm"], dtype=np.float64) / 1000.0
    scan = LaserScan(1, "r1", s["stamp"], s["angle_min"], s["angle_increment"], s["range_min"],
                     s["range_max"], ranges.astype("f4"))  # fmt: skip
    odom = Odometry(1, "r1", o["stamp"], o["x"], o["y"], o["yaw"], o["linear_mps"],
                    o["angular_rps"])  # fmt: skip
    path = PlannedPath(1, "r1", p["stamp"], 1, "goal", p["target_x"], p["target_y"],
                       tuple(p["xs"]), tuple(p["ys"]), p["length_m"])  # fmt: skip
    return scan, odom, path


TICK = Path(__file__).with_name("dynabarn_hard_000_tick.json")


def test_in_the_open_the_box_turns_by_later_decisions_not_a_bend() -> None:
    # the merged tree chose "2 m/s straight on for 0.4 s, then +0.48 rad/s" here, its turn
    # in the open, over the arc toward the path (2 m/s, +0.14 rad/s): straight on at top
    # speed into the mover's wake, where dodge held it behind the mover until the mover
    # turned back into it (collision at 4.5 s). A bend is kept only where the box could not
    # turn in place at its bend: a hit within its circumscribed reach and the margin.
    scan, odom, path = recorded_tick()
    # the default (GOTO_FAST's): bends wherever they score best, the merged tree's choice
    anywhere = choose(scan, odom, JACKAL, path, DwaParams.read({}), BOX)
    assert anywhere is not None and anywhere.best is not None
    assert anywhere.best >= anywhere.window.arcs  # a bend, its turn in the open
    p = DwaParams.read({"dwa_bends_in_open": 0})  # GOTO_DODGE's
    choice = choose(scan, odom, JACKAL, path, p, BOX)
    assert choice is not None and choice.best is not None
    win = choice.window
    assert choice.best < win.arcs  # a single arc
    assert (win.v[choice.best], win.w[choice.best]) == pytest.approx((2.0, 0.14), abs=0.01)
    command = command_for(choice, path)
    assert "then" not in command.reason and "this for" not in command.reason
    # every "straight on, then turn" left in the window bends within reach of a hit
    if win.then_w is not None:
        turns = np.flatnonzero(win.then_w != 0.0) + win.arcs
        x, y, _ = tr.rollout(
            tr.Window(win.v[turns], win.w[turns]), tr.start_pose(odom.linear_mps,
            odom.angular_rps, p.delay_s), win.bend_s, 1,
        )  # fmt: skip
        hits = obstacles(scan, 5.0)
        reach = max(math.hypot(a, b) for a, b in BOX) + p.margin_m
        for bx, by in zip(x[:, -1], y[:, -1], strict=True):
            assert np.hypot(hits[:, 0] - bx, hits[:, 1] - by).min() <= reach + 1e-9
    plain = dwa_reference.choose(scan, odom, JACKAL, path, p, BOX)
    assert plain is not None and plain.best == choice.best

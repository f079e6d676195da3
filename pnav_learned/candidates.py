"""learned_drive's check: the network proposes, geometry checks.

The model's (linear, angular) is a proposal, not a command. It and the points of dwa's own
lattice (the dynamic window dwa would sample for the same odometry, robot row and ``dwa_*``
params: pnav_local.trajectories.window) are ranked by how near each is to the proposal, in
lattice cells, and put, nearest first, to dwa's own admissibility, with dwa's own functions: the
footprint (the robot row's polygon, or its disc) rolled out along each arc for the horizon
against the scan's hits with the margin (pnav_local.clearance), the stopping distance of the
window's slowest speed (pnav_local.trajectories.admissible), a slow arc followed on as far
as the robot goes in ``dwa_min_travel_s`` (trajectories.further), and dwa's speed cap (the
path's end, and safety_stop's reach straight ahead: pnav_local.dwa.stopping_speed). The
nearest admissible candidate is recommended. Standing still is no move: it is ranked last,
and if it is all that passes (or nothing does) the verdict is a brake that says so.

Why nearest first: checking is the expensive half of a dwa decision (some 170 arcs of 10
poses each against the scan). Here the proposal is checked alone first; only if it fails
are the others, a few at a time (BATCHES), until one passes. Most decisions in the open
stop at the first check, many others within the first batch; a robot in a pocket, whose
proposal keeps pointing into it, has the whole lattice checked. What a decision costs,
checks included, is what ``python -m pnav.bench.learned`` measures (docs/BENCHMARKS.md: half
of dwa's on the held-out BARN worlds, as the proposal fails half the time).

A classifier over dwa's lattice (pnav_learned.lattice) is checked with the same functions:
its likeliest cells as one batch, through :class:`Scene` (pnav_learned.drive.from_lattice).

dwa itself is not edited or called: its scoring (progress, path, heading, clearance) is what
the network replaces, and this module imports only the geometry.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

import pnav_local.clearance as clearance
import pnav_local.trajectories as tr
from common.contract.records import LaserScan, Odometry, Robot
from common.scan import readings
from pnav_local.dwa import stopping_speed
from pnav_local.dwa_params import DwaParams

# how many of the ranked lattice points are checked at once once the proposal has failed:
# the nearest few first (usually one of them passes), then more at a time; the rest of the
# lattice in one go
BATCHES = (4, 12, 32)
# from this many poses a batch's gaps are measured through dwa's sorted index of the hits
# (clearance.Index, built once a decision when first needed) rather than pose by hit
INDEXED_FROM = 100


@dataclass(frozen=True)
class Verdict:
    """What the check found: the velocity to recommend, and how it was found."""

    linear: float
    angular: float
    # the chosen candidate's rank (0: the proposal itself, within the window); None: no
    # candidate that moves is admissible (linear and angular are then a brake)
    rank: int | None
    checked: int  # candidates rolled out against the scan
    gap_m: float  # the chosen arc's smallest gap beyond the footprint (inf: nothing near)

    @property
    def admitted(self) -> bool:
        return self.rank is not None


def ranked(
    proposal: tuple[float, float], win: tr.Window, v_cell: float, w_cell: float
) -> tuple[tr.FloatArray, tr.FloatArray]:
    """The window's points, nearest the proposal first (distance in lattice cells), standing
    still (no speed, no turn) last: it is what a brake does, not a move."""
    d = np.hypot((win.v - proposal[0]) / v_cell, (win.w - proposal[1]) / w_cell)
    still = (np.abs(win.v) < 1e-9) & (np.abs(win.w) < 1e-9)
    order = np.lexsort((d, still))  # by stillness, then distance
    return win.v[order], win.w[order]


@functools.lru_cache(maxsize=8)
def _beams(angle_min: float, increment: float, count: int) -> tuple[tr.FloatArray, tr.FloatArray]:
    """Each beam's unit vector: the same for every scan of one lidar."""
    angles = angle_min + increment * np.arange(count)
    return np.cos(angles), np.sin(angles)


@functools.lru_cache(maxsize=8)
def _outline(
    radius_m: float, polygon: tuple[tuple[float, float], ...] | None
) -> tuple[clearance.Footprint, tuple[float, float, float, float] | None]:
    """The footprint, and its box (centre x, y, half length, width) if it is one along the
    robot's axes (clearance's closed form): worked out once per robot row, not per scan."""
    foot = clearance.Footprint.of(radius_m, polygon)
    box = None if foot.polygon is None else clearance._box(foot.polygon)
    return foot, box


def hits(scan: LaserScan, reach_m: float) -> tuple[tr.FloatArray, tr.FloatArray]:
    """The scan's hits within ``reach_m`` of the lidar, robot frame."""
    r = scan.ranges.astype(np.float64)
    cos, sin = _beams(scan.angle_min, scan.angle_increment, len(r))
    near = np.flatnonzero(
        readings(r, scan.range_min) & (r <= min(scan.range_max, reach_m))
    )  # NaN and inf compare false: no reading, or nothing within reach
    r = r[near]
    return r * cos[near], r * sin[near]


def gaps(
    poses: tuple[tr.FloatArray, tr.FloatArray, tr.FloatArray],
    points: tuple[tr.FloatArray, tr.FloatArray],
    foot: clearance.Footprint,
    box: tuple[float, float, float, float] | None,
    needed_m: float,
) -> tr.FloatArray:
    """Per pose (flat), the gap between its footprint and the nearest point: exact below
    ``needed_m``, at least ``needed_m`` otherwise (inf with no point near), as
    clearance.gaps. Every pose against every point in the poses' bounding box, the centres'
    distances first and the outline's only for the pairs within reach (a box's:
    :func:`_box_gaps`): for a few dozen poses this costs less than the sorted index dwa
    builds for its hundreds (used for larger batches)."""
    xs, ys, yaws = poses
    px, py = points
    out = np.full(len(xs), np.inf)
    reach = foot.reach_m + needed_m
    # only the points within reach of the poses' bounding box can be within reach of a pose
    x0, x1 = float(xs.min()) - reach, float(xs.max()) + reach
    y0, y1 = float(ys.min()) - reach, float(ys.max()) + reach
    near = np.flatnonzero(
        (np.abs(px - (x0 + x1) / 2.0) <= (x1 - x0) / 2.0)
        & (np.abs(py - (y0 + y1) / 2.0) <= (y1 - y0) / 2.0)
    )
    if len(near) == 0:
        return out
    if foot.polygon is not None and box is not None:
        return _box_gaps(poses, (px[near], py[near]), box, reach, out)
    dx = px[near][None, :] - xs[:, None]
    dy = py[near][None, :] - ys[:, None]
    if foot.polygon is None:
        disc: tr.FloatArray = np.sqrt((dx * dx + dy * dy).min(axis=1)) - foot.radius_m
        return disc
    c, s = np.cos(yaws)[:, None], np.sin(yaws)[:, None]
    qx, qy = c * dx + s * dy, c * dy - s * dx  # each point in the pose's frame
    general = clearance._polygon_gap(qx.ravel(), qy.ravel(), foot.polygon)
    polygon_gaps: tr.FloatArray = general.reshape(qx.shape).min(axis=1)
    return polygon_gaps


def _box_gaps(
    poses: tuple[tr.FloatArray, tr.FloatArray, tr.FloatArray],
    points: tuple[tr.FloatArray, tr.FloatArray],
    box: tuple[float, float, float, float],
    reach: float,
    out: tr.FloatArray,
) -> tr.FloatArray:
    """gaps() for a box along the robot's axes: the outline's arithmetic (clearance's
    closed form) only for the (pose, point) pairs whose centres are within ``reach``: a
    point farther from a pose's centre is farther than the margin from its outline, which is
    all that is said of it, and most pairs are (a few arcs in the open come near a few dozen
    hits). The pairs are found in single precision, with a centimetre to spare; each found
    pair is measured in double, as clearance measures it."""
    xs, ys, yaws = poses
    px, py = points
    dx = px.astype(np.float32)[None, :] - xs.astype(np.float32)[:, None]
    dy = py.astype(np.float32)[None, :] - ys.astype(np.float32)[:, None]
    dx *= dx
    dy *= dy
    dx += dy
    pose, point = np.nonzero(dx <= np.float32((reach + 0.01) ** 2))
    if len(pose) == 0:
        return out
    # the pairs in row order: each pose's are one run
    ddx, ddy = px[point] - xs[pose], py[point] - ys[pose]
    c, s = np.cos(yaws[pose]), np.sin(yaws[pose])
    qx, qy = c * ddx + s * ddy, c * ddy - s * ddx  # each point in the pose's frame
    # the box's signed distance, in place: outside, the distance to the nearest side or
    # corner; inside, minus the distance to the nearest side
    cx, cy, hx, hy = box
    ex, ey = np.abs(qx - cx) - hx, np.abs(qy - cy) - hy
    inside = np.minimum(np.maximum(ex, ey), 0.0)
    np.maximum(ex, 0.0, out=ex)
    np.maximum(ey, 0.0, out=ey)
    ex *= ex
    ey *= ey
    ex += ey
    np.sqrt(ex, out=ex)
    ex += inside
    starts = np.flatnonzero(np.diff(pose, prepend=-1))
    out[pose[starts]] = np.minimum.reduceat(ex, starts)
    return out


def bounds(
    odom: Odometry, robot: Robot, p: DwaParams, v_cap: float
) -> tuple[float, float, float, float]:
    """(slowest, fastest, lowest turn, highest turn) of the dynamic window dwa samples:
    trajectories.window's arithmetic on four numbers (the grid is made only if needed)."""
    top = max(0.0, min(robot.max_linear_mps, v_cap))
    v_low = min(max(0.0, odom.linear_mps - robot.max_linear_accel_mps2 * p.window_s), top)
    v_high = min(top, max(0.0, odom.linear_mps) + robot.max_linear_accel_mps2 * p.window_s)
    w_reach = robot.max_angular_accel_rps2 * p.window_s
    w_low = max(-robot.max_angular_rps, odom.angular_rps - w_reach)
    w_high = min(robot.max_angular_rps, odom.angular_rps + w_reach)
    return v_low, max(v_low, v_high), min(w_low, w_high), max(w_low, w_high)


class Scene:
    """One decision's checks: what every candidate of it is put to (the hits near the
    window, the footprint, the start pose, dwa's speed cap and window), worked out once;
    :meth:`admissible` rolls a set of candidates out against them."""

    def __init__(
        self,
        scan: LaserScan,
        odom: Odometry,
        robot: Robot,
        p: DwaParams,
        remaining_m: float,
        polygon: Sequence[Sequence[float]] | None = None,
    ) -> None:
        self.robot, self.p, self.odom = robot, p, odom
        top = robot.max_linear_mps
        shape = None if polygon is None else tuple((float(x), float(y)) for x, y in polygon)
        self.foot, self.box = _outline(robot.footprint_radius_m, shape)
        accel = robot.max_linear_accel_mps2
        self.start = tr.start_pose(odom.linear_mps, odom.angular_rps, p.delay_s)
        self.needed = p.margin_m + 0.01
        # the hits an arc of this window can come near: the farthest the window reaches
        v_top = min(top, max(0.0, odom.linear_mps) + accel * p.window_s)
        travel = max(v_top * p.horizon_s, p.min_travel_s * top)
        reach = math.hypot(self.start[0], self.start[1]) + travel + self.foot.reach_m + self.needed
        self.points = hits(scan, p.obstacle_range_m or reach)
        radius = robot.footprint_radius_m
        v_cap = math.sqrt(2.0 * accel * max(0.0, remaining_m)) * 0.8
        px, py = self.points
        ahead = (px > 0.0) & (np.abs(py) < radius)
        straight = float(np.hypot(px[ahead], py[ahead]).min(initial=math.inf))
        straight = max(0.0, straight - radius - p.safety_margin_m)
        self.v_cap = min(v_cap, stopping_speed(straight, p.safety_lookahead_s, accel))
        self.bounds = bounds(odom, robot, p, self.v_cap)
        self._index: clearance.Index | None = None  # dwa's index of the hits, once needed

    def admissible(self, v: tr.FloatArray, w: tr.FloatArray) -> tuple[tr.BoolArray, tr.FloatArray]:
        """dwa's test of each arc (trajectories.admissible and the slow arcs' rule), and
        each arc's smallest gap. The window's brake is in every set put to
        trajectories.admissible (its "stops in time" holds for a set's slowest speed only),
        as a row of its own that is not rolled out."""
        p, start, top = self.p, self.start, self.robot.max_linear_mps
        win = tr.Window(v, w)
        poses = tr.rollout(win, start, p.horizon_s, p.steps)
        slow, on = tr.further(win, start, p.min_travel_s * top, p.horizon_s, p.steps)
        if p.min_travel_s <= 0:
            slow = slow[:0]
        flat = tuple(
            np.concatenate([poses[k].ravel(), [start[k]], on[k][: len(slow)].ravel()])
            for k in range(3)
        )
        if len(flat[0]) < INDEXED_FROM:
            every = gaps((flat[0], flat[1], flat[2]), self.points, self.foot, self.box, self.needed)
        else:
            if self._index is None:
                reach = self.foot.reach_m + self.needed
                self._index = clearance.Index(np.column_stack(self.points), reach)
            every = clearance.gaps(flat[0], flat[1], flat[2], self._index, self.foot, self.needed)
        n = poses[0].size
        arc_gaps, start_gap = every[:n].reshape(poses[0].shape), float(every[n])
        ok = tr.admissible(
            tr.Window(np.append(v, self.bounds[0]), np.append(w, 0.0)),
            np.vstack([arc_gaps, np.full((1, p.steps), np.inf)]),
            start_gap, margin_m=p.margin_m, accel_v=self.robot.max_linear_accel_mps2,
            delay_s=p.delay_s, horizon_s=p.horizon_s,
        )[:-1]  # fmt: skip
        if len(slow):
            limit = min(p.margin_m, start_gap - 0.005)
            ok[slow] &= every[n + 1 :].reshape(len(slow), p.steps).min(axis=1) >= limit
        return ok, arc_gaps.min(axis=1)


def check(
    proposal: tuple[float, float],
    scan: LaserScan,
    odom: Odometry,
    robot: Robot,
    p: DwaParams,
    remaining_m: float,
    polygon: Sequence[Sequence[float]] | None = None,
) -> Verdict:
    """The nearest admissible velocity to ``proposal`` among it and its lattice neighbours.
    ``remaining_m``: how far the path's end is (the speed cap near it)."""
    scene = Scene(scan, odom, robot, p, remaining_m, polygon)
    admissible = scene.admissible
    v_low, v_high, w_low, w_high = scene.bounds
    top, accel = robot.max_linear_mps, robot.max_linear_accel_mps2
    # the proposal first, clamped into the window; its neighbours, nearest first, a few at
    # a time, only while none has passed
    v0, w0 = min(max(proposal[0], v_low), v_high), min(max(proposal[1], w_low), w_high)
    ok, arc_gaps = admissible(np.array([v0]), np.array([w0]))
    if ok[0]:
        return Verdict(v0, w0, 0, 1, float(arc_gaps[0]))
    lattice = tr.window(
        odom.linear_mps, odom.angular_rps, max_v=top, max_w=robot.max_angular_rps,
        accel_v=accel, accel_w=robot.max_angular_accel_rps2, dt=p.window_s,
        v_samples=p.linear_samples, w_samples=p.angular_samples, v_cap=scene.v_cap,
    )  # fmt: skip
    cells = (
        max((v_high - v_low) / max(1, p.linear_samples - 1), 1e-3),
        max((w_high - w_low) / max(1, p.angular_samples - 1), 1e-3),
    )
    v, w = ranked((v0, w0), lattice, *cells)
    checked, at = 1, 0
    for k in range(len(BATCHES) + 1):
        if at >= len(v):
            break
        size = BATCHES[k] if k < len(BATCHES) else len(v) - at
        ok, arc_gaps = admissible(v[at : at + size], w[at : at + size])
        checked += len(ok)
        moving = ok & ((np.abs(v[at : at + size]) >= 1e-9) | (np.abs(w[at : at + size]) >= 1e-9))
        if moving.any():
            i = int(np.flatnonzero(moving)[0])
            return Verdict(
                float(v[at + i]), float(w[at + i]), at + i + 1, checked, float(arc_gaps[i])
            )
        at += size
    return Verdict(0.0, 0.0, None, checked, math.inf)

"""A slow, straightforward dwa decision, for the tests only: what pnav_local.dwa.choose
decides, written the plain way (every pose against every hit in float64, each arc scored in
full, the path densified leg by leg), so a faster product that decides anything else fails
tests/unit/local/test_dwa_reference.py.

It shares with the product only what it does not try to speed up: the window (a box's
two-segment roll-outs included), the arcs' poses, the path's localisation, the merge of the
hits and the straight-ahead gap.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

import pnav_local.trajectories as tr
import pnav_local.veto as veto
from common import sweep
from common.contract.planned_path import PlannedPath
from common.contract.records import LaserScan, Odometry, Robot
from common.footprint import Footprint
from pnav_local.dwa import Choice, bent_window, path_in_robot_frame, stopping_speed
from pnav_local.dwa_params import DwaParams

Array = tr.FloatArray


def obstacles(scan: LaserScan, reach_m: float) -> Array:
    ranges = scan.ranges.astype(np.float64)
    angles = scan.angle_min + scan.angle_increment * np.arange(len(ranges))
    angles = np.arctan2(np.sin(angles), np.cos(angles))
    valid = (
        np.isfinite(ranges)
        & (ranges >= scan.range_min - 1e-4)
        & (ranges <= min(scan.range_max, reach_m))
    )
    r, a = ranges[valid], angles[valid]
    return tr.merge_obstacles(np.column_stack([r * np.cos(a), r * np.sin(a)]))


def polygon_gap(x: Array, y: Array, polygon: Sequence[Sequence[float]]) -> Array:
    """Signed distance of points (robot frame) from the outline, negative inside: edge by
    edge, and an even-odd count of the edges a ray toward +x crosses."""
    best = np.full(x.shape, np.inf)
    inside = np.zeros(x.shape, dtype=bool)
    n = len(polygon)
    for i in range(n):
        (ax, ay), (bx, by) = polygon[i], polygon[(i + 1) % n]
        ex, ey = bx - ax, by - ay
        t = np.clip(((x - ax) * ex + (y - ay) * ey) / max(ex * ex + ey * ey, 1e-18), 0.0, 1.0)
        best = np.minimum(best, np.hypot(x - ax - t * ex, y - ay - t * ey))
        if ay != by:
            crosses = ((ay > y) != (by > y)) & (x < ax + (y - ay) * (bx - ax) / (by - ay))
            inside ^= crosses
    out: Array = np.where(inside, -best, best)
    return out


def gaps(
    xs: Array,
    ys: Array,
    yaws: Array,
    points: Array,
    radius: float,
    polygon: Sequence[Sequence[float]] | None,
) -> Array:
    """Per pose, the gap between its footprint and the nearest hit (inf with none)."""
    if len(points) == 0:
        return np.full(xs.shape, np.inf)
    dx = points[None, :, 0] - xs.reshape(-1, 1)
    dy = points[None, :, 1] - ys.reshape(-1, 1)
    if polygon is None:
        out: Array = (np.hypot(dx, dy).min(axis=1) - radius).reshape(xs.shape)
        return out
    c, s = np.cos(yaws.reshape(-1, 1)), np.sin(yaws.reshape(-1, 1))
    qx, qy = c * dx + s * dy, -s * dx + c * dy
    flat: Array = polygon_gap(qx, qy, polygon).min(axis=1).reshape(xs.shape)
    return flat


def densify(points: Array, step_m: float = 0.05) -> Array:
    if len(points) < 2:
        return points
    length = float(np.hypot(*np.diff(points, axis=0).T).sum())
    step_m = max(step_m, length / 1000)
    parts = [points[:1]]
    for a, b in itertools.pairwise(points):
        n = max(1, math.ceil(float(np.hypot(*(b - a))) / step_m))
        parts.append(a + np.linspace(0.0, 1.0, n + 1)[1:, None] * (b - a))
    return np.vstack(parts)


def choose(
    scan: LaserScan,
    odom: Odometry,
    robot: Robot,
    path: PlannedPath,
    p: DwaParams,
    polygon: Sequence[Sequence[float]] | None = None,
) -> Choice | None:
    top, radius, accel = robot.max_linear_mps, robot.footprint_radius_m, robot.max_linear_accel_mps2
    outline = radius if polygon is None else max(math.hypot(x, y) for x, y in polygon)
    lookahead = p.lookahead_m or max(0.8, top * (p.horizon_s + p.delay_s) + 0.3)
    local = tr.localise(path_in_robot_frame(path, odom), lookahead, p.sight_m)
    if local is None:
        return None
    reach = p.obstacle_range_m or (top * (p.horizon_s + p.delay_s) + outline + 0.5)
    points = obstacles(scan, reach)
    v_cap = math.sqrt(2.0 * accel * max(0.0, local.remaining_m)) * 0.8
    straight = max(0.0, tr.straight_gap(points, radius) - radius - p.safety_margin_m)
    v_cap = min(v_cap, stopping_speed(straight, p.safety_lookahead_s, accel))
    win = tr.window(
        odom.linear_mps, odom.angular_rps, max_v=top, max_w=robot.max_angular_rps,
        accel_v=accel, accel_w=robot.max_angular_accel_rps2, dt=p.window_s,
        v_samples=p.linear_samples, w_samples=p.angular_samples, v_cap=v_cap,
        extra_w=math.atan2(local.facing[1], local.facing[0]) / p.horizon_s,
    )  # fmt: skip
    start = tr.start_pose(odom.linear_mps, odom.angular_rps, p.delay_s)
    if polygon is not None:  # the box's two-segment roll-outs: part of the window
        win = bent_window(win, p, robot, local, start, points, outline)
    near = math.hypot(start[0], start[1]) + float(win.v.max()) * p.horizon_s + outline + 0.5
    points = points[np.hypot(points[:, 0], points[:, 1]) <= near]
    xs, ys, yaws = tr.rollout(win, start, p.horizon_s, p.steps)
    g = gaps(xs, ys, yaws, points, radius, polygon)
    at = np.array([[start[0]]]), np.array([[start[1]]]), np.array([[start[2]]])
    start_gap = float(gaps(*at, points, radius, polygon)[0, 0])

    ok, squeezed = _admitted(win, g, start_gap, start, points, radius, polygon, p, accel, top)
    if not ok.any():
        return Choice(win, ok, None, None, local, v_cap)
    weights = p.weights
    dense = densify(local.points)
    blocked = bool(
        len(points) > 0
        and len(dense) > 0
        and np.hypot(
            dense[:, None, 0] - points[None, :, 0], dense[:, None, 1] - points[None, :, 1]
        ).min()
        < radius + p.margin_m
    )
    if blocked:
        weights = replace(weights, path=weights.path * p.blocked_path_factor)
    scores = score(win, (xs, ys, yaws), g, local, start, top, p, weights)
    best: int | None = int(np.argmax(np.where(ok, scores.total, -np.inf)))
    vetoed = 0
    if polygon is not None:
        best, vetoed = _vetted(scan, robot, Footprint.of(robot.footprint_radius_m, polygon),
                               win, ok, scores.total)  # fmt: skip
    return Choice(win, ok, scores, best, local, v_cap, blocked, vetoed, squeezed)


def _admitted(
    win: tr.Window,
    g: Array,
    start_gap: float,
    start: tuple[float, float, float],
    points: Array,
    radius: float,
    polygon: Sequence[Sequence[float]] | None,
    p: DwaParams,
    accel: float,
    top: float,
) -> tuple[Array, bool]:
    """Admissible arc by arc, and whether with the squeeze margin (a box moving nowhere
    with the margin)."""

    def admitted(margin: float) -> Array:
        """Clear by the margin all along, or the brake stopping before the first hit."""
        limit = min(margin, start_gap - 0.005)
        ok = np.zeros(len(win.v), dtype=bool)
        for i, v in enumerate(win.v):
            hits = np.flatnonzero(g[i] < limit)
            if len(hits) == 0:
                ok[i] = True
            elif v <= win.v.min() + 1e-9:
                travel = abs(v) * p.horizon_s * hits[0] / p.steps
                ok[i] = v * v / (2.0 * accel) + abs(v) * p.delay_s < travel
        if p.min_travel_s > 0:
            travel = p.min_travel_s * top
            for i, (v, w) in enumerate(zip(win.v, win.w, strict=True)):
                if not (abs(v) > 1e-6 and abs(v) * p.horizon_s < travel):
                    continue
                turn_s = math.pi / max(abs(w), 1e-6) if abs(w) > 1e-6 else math.inf
                end_s = max(min(travel / abs(v), turn_s), p.horizon_s)
                t = end_s * np.linspace(1.0 / p.steps, 1.0, p.steps)
                ax, ay, ayaw = tr.arcs(np.array([v]), np.array([w]), t)
                c, s = math.cos(start[2]), math.sin(start[2])
                px, py = start[0] + c * ax - s * ay, start[1] + s * ax + c * ay
                ok[i] &= bool(gaps(px, py, start[2] + ayaw, points, radius, polygon).min() >= limit)
        return ok

    ok = admitted(p.margin_m)
    moving = win.v > 0
    if polygon is not None and 0.0 < p.squeeze_margin_m < p.margin_m and not ok[moving].any():
        wider = admitted(p.squeeze_margin_m)  # nothing moves with the margin: squeeze
        if wider[moving].any():
            return wider, True
    return ok, False


def _vetted(
    scan: LaserScan, robot: Robot, foot: Footprint, win: tr.Window, ok: Array, total: Array
) -> tuple[int | None, int]:
    """The safety layer's test put to the admissible arcs best first, every return of the
    scan considered (veto.py keeps only those near enough to matter)."""
    returns = sweep.Returns.of_ranges(
        scan.ranges.astype(np.float64), scan.angle_min, scan.angle_increment, scan.range_min
    )
    ranked = sorted(np.flatnonzero(ok).tolist(), key=lambda i: (-total[i], i))
    for tried, i in enumerate(ranked[: veto.MAX_TRIES]):
        if sweep.passes(returns, foot, float(win.v[i]), float(win.w[i]),
                        margin_m=sweep.MARGIN_M, latency_s=sweep.LATENCY_S,
                        decel_mps2=robot.max_linear_accel_mps2):  # fmt: skip
            return i, tried
    return None, min(len(ranked), veto.MAX_TRIES)


def score(
    win: tr.Window,
    poses: tuple[Array, Array, Array],
    g: Array,
    local: tr.Local,
    start: tuple[float, float, float],
    top: float,
    p: DwaParams,
    weights: tr.Weights,
) -> tr.Scores:
    """Every term of every arc, all from the full gaps (trajectories.py's docstring)."""
    xs, ys, yaws = poses
    cx, cy = local.carrot
    reach = max(top * p.horizon_s, 1e-6)
    before = math.hypot(cx - start[0], cy - start[1])
    progress = (before - np.hypot(cx - xs[:, -1], cy - ys[:, -1])) / reach
    a, b = local.points[:-1], local.points[1:]
    path = np.empty(len(xs))
    for i, (ex, ey) in enumerate(zip(xs[:, -1], ys[:, -1], strict=True)):
        if len(local.points) == 1:
            path[i] = math.hypot(ex - local.points[0, 0], ey - local.points[0, 1])
            continue
        ab = b - a
        t = np.clip(((ex - a[:, 0]) * ab[:, 0] + (ey - a[:, 1]) * ab[:, 1])
                    / np.maximum((ab * ab).sum(axis=1), 1e-12), 0.0, 1.0)  # fmt: skip
        path[i] = np.hypot(ex - a[:, 0] - t * ab[:, 0], ey - a[:, 1] - t * ab[:, 1]).min()
    path /= reach
    cx, cy = local.facing
    bearing = np.arctan2(cy - ys, cx - xs) - yaws
    along = np.abs(np.arctan2(np.sin(bearing), np.cos(bearing))) / math.pi
    along = np.where(np.hypot(cx - xs, cy - ys) < 0.1 * reach, 0.0, along)
    heading = along.mean(axis=1)
    speed = win.v / max(top, 1e-6)
    cap = p.clearance_cap_m
    gap = np.clip(g.min(axis=1), 0.0, cap) / cap * speed
    total = (
        weights.progress * progress
        - weights.path * path
        - weights.heading * heading
        + weights.clearance * gap
        + weights.speed * speed
    )
    return tr.Scores(progress, path, heading, gap, speed, total)

"""Time to collision with moving obstacles, and the evasive command (the dodge scenario's
judgement; docs/CONTROLLER.md, "dodge").

Everything here is in the robot's frame at the scan (x ahead, y left), a fixed frame for the
prediction: each moving track is a disc (its radius plus the footprint plus a margin that
grows with time: the prediction's error grows with it) at constant velocity, and the robot
follows a *motion*: a target velocity reached within its acceleration limits after the
scan-to-wheels delay. A motion's time to collision is the first predicted time its
footprint meets a mover's disc within the horizon (inf: none). The static hits of the scan
(the beams not on a moving cluster) must stay clear of any evasive motion other than the
stop, or be no nearer than they are now.

Bounded: a fixed set of motions (``SPEEDS`` x ``TURNS``) of ``STEPS`` poses, against at most
tracks.MAX_TRACKS movers and ``MAX_STATIC`` static hits (the nearest, merged on a grid).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from common.contract.records import Robot

FloatArray = npt.NDArray[np.float64]

HORIZON_S = 2.0
STEPS = 20
DELAY_S = 0.05  # scan to wheels: the robot keeps its velocity meanwhile
MARGIN_M = 0.15  # kept beyond the two discs at once...
MARGIN_MPS = 0.05  # ...plus this for each second ahead (the prediction's growing error)
STATIC_MARGIN_M = 0.02
MAX_STATIC = 1024
GRID_M = 0.04
SPEEDS = (1.0, 0.85, 0.7, 0.55, 0.4, 0.25, 0.1, 0.0)  # shares of the top speed
TURNS = (0.0, 0.5, -0.5)  # shares of the top turn rate, and the measured one
BACK_SHARE = 0.4  # backing out, where the lidar sees behind


@dataclass(frozen=True)
class Mover:
    """A moving track in the robot's frame at the scan."""

    track: int
    x: float
    y: float
    vx: float
    vy: float
    radius: float


@dataclass(frozen=True)
class Motion:
    v: float
    w: float
    ttc: float  # first predicted contact with a mover, s (inf: none within the horizon)
    mover: int | None  # the track it meets first


def rollout(v0: float, w0: float, v: float, w: float, robot: Robot) -> FloatArray:
    """The robot's positions (STEPS x 2) over the horizon, from rest at the origin facing +x
    at (v0, w0), the target (v, w) reached at the robot's accelerations after the delay."""
    dt = HORIZON_S / STEPS
    out = np.empty((STEPS, 2))
    x = y = th = 0.0
    cv, cw = v0, w0
    av, aw = robot.max_linear_accel_mps2, robot.max_angular_accel_rps2
    t = 0.0
    for k in range(STEPS):
        t += dt
        if t > DELAY_S:
            cv += max(-av * dt, min(av * dt, v - cv))
            cw += max(-aw * dt, min(aw * dt, w - cw))
        mid = th + cw * dt / 2.0
        x += cv * dt * math.cos(mid)
        y += cv * dt * math.sin(mid)
        th += cw * dt
        out[k] = (x, y)
    return out


def times() -> FloatArray:
    return np.asarray(np.arange(1, STEPS + 1) * (HORIZON_S / STEPS), dtype=np.float64)


def ttc(poses: FloatArray, movers: list[Mover], footprint_m: float) -> tuple[float, int | None]:
    """The first predicted contact of the poses with a mover: (time, track) or (inf, None)."""
    if not movers:
        return math.inf, None
    ts = times()
    m = np.asarray([(k.x, k.y, k.vx, k.vy, k.radius) for k in movers], dtype=np.float64)
    mx = m[:, 0][None, :] + m[:, 2][None, :] * ts[:, None]  # steps x movers
    my = m[:, 1][None, :] + m[:, 3][None, :] * ts[:, None]
    gap = np.hypot(poses[:, 0:1] - mx, poses[:, 1:2] - my)
    reach = m[:, 4][None, :] + footprint_m + MARGIN_M + MARGIN_MPS * ts[:, None]
    hit = gap < reach
    # contact at the start too: a mover already touching the margin counts at once
    now = np.hypot(m[:, 0], m[:, 1]) < m[:, 4] + footprint_m + MARGIN_M
    if now.any():
        return 0.0, movers[int(np.flatnonzero(now)[0])].track
    rows = np.flatnonzero(hit.any(axis=1))
    if len(rows) == 0:
        return math.inf, None
    k = int(rows[0])
    return float(ts[k]), movers[int(np.flatnonzero(hit[k])[0])].track


def static_points(xy: FloatArray) -> FloatArray:
    """The static hits merged on a grid, the nearest ``MAX_STATIC``."""
    if len(xy) == 0:
        return xy
    cells = np.unique(np.floor(xy / GRID_M).astype(np.int64), axis=0)
    pts = (cells + 0.5) * GRID_M
    order = np.argsort(np.hypot(pts[:, 0], pts[:, 1]), kind="stable")
    return np.asarray(pts[order[:MAX_STATIC]], dtype=np.float64)


def clear_of_static(poses: FloatArray, points: FloatArray, footprint_m: float) -> bool:
    """No pose nearer a static hit than the footprint plus a margin, or than the robot is now
    (a robot already that close may move if it gets no closer)."""
    if len(points) == 0:
        return True
    dist = np.hypot(points[:, 0], points[:, 1])
    now = float(dist.min())
    limit = min(footprint_m + STATIC_MARGIN_M, now - 0.005)
    # only what the poses can come near matters
    points = points[dist <= float(np.hypot(poses[:, 0], poses[:, 1]).max()) + limit]
    if len(points) == 0:
        return True
    d = np.hypot(poses[:, 0:1] - points[None, :, 0], poses[:, 1:2] - points[None, :, 1])
    return bool(d.min() >= limit)


def choose(
    v0: float,
    w0: float,
    robot: Robot,
    movers: list[Mover],
    points: FloatArray,
    sees_behind: bool,
) -> Motion:
    """The evasive motion to recommend. Of the motions that meet no mover within the
    horizon, the straightest (a swerve leaves the path; slowing on it does not), then the
    fastest forward; if every one meets a mover, the one meeting it latest (then the
    straighter, then the faster). A motion other than the stop must keep clear of the
    static hits: tested in that order of preference until one does (the stop always does),
    so a decision seldom tests more than a few."""
    top, wmax = robot.max_linear_mps, robot.max_angular_rps
    speeds = [s * top for s in SPEEDS] + ([-BACK_SHARE * top] if sees_behind else [])
    judged: list[tuple[Motion, FloatArray]] = []
    for v in speeds:
        for w in [s * wmax for s in TURNS] if v != 0.0 else [0.0]:
            poses = rollout(v0, w0, v, w, robot)
            t, k = ttc(poses, movers, robot.footprint_radius_m)
            judged.append((Motion(v, w, t, k), poses))
    safe = [mp for mp in judged if math.isinf(mp[0].ttc)]
    if safe:
        order = sorted(safe, key=lambda mp: (-abs(mp[0].w), mp[0].v), reverse=True)
    else:
        order = sorted(judged, key=lambda mp: (mp[0].ttc, -abs(mp[0].w), mp[0].v), reverse=True)
    for motion, poses in order:
        if motion.v == 0.0 or clear_of_static(poses, points, robot.footprint_radius_m):
            return motion
    stop = next(m for m, _ in judged if m.v == 0.0)
    return stop


def expected(v0: float, w0: float, robot: Robot, movers: list[Mover]) -> Motion:
    """What the robot is about to do without this scenario, judged: the worse of keeping its
    measured velocity and speeding up to its top speed on the same turn (a local controller
    on a clear way does)."""
    worst: Motion | None = None
    for v in (v0, robot.max_linear_mps if v0 >= -0.01 else v0):
        t, k = ttc(rollout(v0, w0, v, w0, robot), movers, robot.footprint_radius_m)
        if worst is None or t < worst.ttc:
            worst = Motion(v, w0, t, k)
    assert worst is not None
    return worst

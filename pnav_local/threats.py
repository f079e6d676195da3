"""Time to collision with moving obstacles, and the evasive command (the dodge scenario's
judgement; docs/CONTROLLER.md, "dodge").

Everything here is in the robot's frame at the scan (x ahead, y left), a fixed frame for the
prediction: each moving track is a disc (its radius plus a margin that grows with time: the
prediction's error grows with it) at constant velocity, and the robot follows a *motion*: a
target velocity reached within its acceleration limits after the scan-to-wheels delay. A
motion's time to collision is the first predicted time the robot's footprint (its polygon,
turned with each pose: a box's corners reach farther than its sides; or its disc) comes
within a mover's disc within the horizon (inf: none). The static hits of the scan
(the beams not on a moving cluster) must stay clear of any evasive motion other than the
stop, or be no nearer than they are now. And a motion must stay out of the controller's
safety_stop's reach in its first ``STOPPABLE_S`` (:func:`stopped_at`: the hits and the
movers' discs in its swept way at each pose, as safety_stop judges a scan): a robot that
safety_stop stops among movers stands, held, in their way.

Bounded: a fixed set of motions (``SPEEDS`` x ``TURNS``) of ``STEPS`` poses, against at most
tracks.MAX_TRACKS movers and ``MAX_STATIC`` static hits (the nearest, merged on a grid).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from common.contract.records import Robot
from common.footprint import Footprint

FloatArray = npt.NDArray[np.float64]

HORIZON_S = 2.0
STEPS = 20
DELAY_S = 0.05  # scan to wheels: the robot keeps its velocity meanwhile
MARGIN_M = 0.15  # kept beyond the two discs at once...
MARGIN_MPS = 0.05  # ...plus this for each second ahead (the prediction's growing error)
STATIC_MARGIN_M = 0.02
CLOSING_M = 0.01  # a mover inside the margin meets the robot once the gap closes by this
MAX_STATIC = 1024
GRID_M = 0.04
SPEEDS = (1.0, 0.85, 0.7, 0.55, 0.4, 0.25, 0.1, 0.0)  # shares of the top speed
# shares of the top turn rate: straight on, and gentle to sharp turns either way (a gentle one
# moves the robot a few tenths of a metre off its line within a second: past a slow mover's
# side rather than waiting seconds for it to cross)
TURNS = (0.0, 0.1, -0.1, 0.25, -0.25, 0.5, -0.5)
BRISK_SHARE = 0.4  # of the top speed: a motion at least this fast keeps the robot going
ON_COURSE_DEG = 45.0  # a straight yield keeps to the path only if the robot faces along it
BACK_SHARE = 0.4  # backing out, where the lidar sees behind
# An evasion's first steps are judged as safety_stop judges each scan: one it would stop
# leaves the robot standing in the movers' way (safety_stop's stop is held 0.5 s)
STOPPABLE_S = 0.5
STOP_MOVING_MPS = 0.01  # safety_stop's: slower, the robot is not translating
OUTLINE_POINTS = 16  # a mover's outline, for the swept way
# beyond safety_stop's reach: the robot overshoots the speed asked for, and a mover's outline
# is where its track says, within a few centimetres
STOP_BUFFER_M = 0.1


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
    # first time safety_stop would stop it for a mover in its swept way (inf: none; judged
    # for what the robot is about to do, ``expected``)
    stop: float = math.inf
    stop_mover: int | None = None

    @property
    def threat(self) -> float:
        """When it first meets a mover, or is stopped for one: the sooner."""
        return min(self.ttc, self.stop)


def rollout(v0: float, w0: float, v: float, w: float, robot: Robot) -> FloatArray:
    """The robot's poses (STEPS x 4: x, y, heading, and the speed there) over the horizon,
    from the origin facing +x at (v0, w0), the target (v, w) reached at the robot's
    accelerations after the delay."""
    dt = HORIZON_S / STEPS
    out = np.empty((STEPS, 4))
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
        out[k] = (x, y, th, cv)
    return out


def times() -> FloatArray:
    return np.asarray(np.arange(1, STEPS + 1) * (HORIZON_S / STEPS), dtype=np.float64)


def _local(poses: FloatArray, xy: FloatArray) -> FloatArray:
    """Points (steps x k x 2, one set per pose) in the robot's frame at each pose."""
    c, sn = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
    dx, dy = xy[..., 0] - poses[:, 0:1], xy[..., 1] - poses[:, 1:2]
    return np.stack([c * dx + sn * dy, -sn * dx + c * dy], axis=-1)


def ttc(
    poses: FloatArray, movers: list[Mover], footprint: Footprint, margin: float = MARGIN_M
) -> tuple[float, int | None]:
    """The first predicted contact of the poses with a mover: (time, track) or (inf, None).
    The footprint is the robot's true outline at each pose (a box's corners reach farther
    than its sides), the mover a disc of its radius plus the margins (``margin`` 0 and the
    growing one: the time the outlines would touch)."""
    if not movers:
        return math.inf, None
    ts = times()
    m = np.asarray([(k.x, k.y, k.vx, k.vy, k.radius) for k in movers], dtype=np.float64)
    # a mover already inside the margin (one beside the robot, or a box taken for one) meets
    # the robot when the gap closes from what it is now, not at once: one leaving, or passing
    # alongside, is no threat; its outline touching the robot's is one at once
    gap0 = footprint.clearance(m[:, 0:2])
    now = gap0 < m[:, 4]
    if now.any():
        return 0.0, movers[int(np.flatnonzero(now)[0])].track
    mx = m[:, 0][None, :] + m[:, 2][None, :] * ts[:, None]  # steps x movers
    my = m[:, 1][None, :] + m[:, 3][None, :] * ts[:, None]
    local = _local(poses, np.stack([mx, my], axis=-1))
    gap = footprint.clearance(local.reshape(-1, 2)).reshape(mx.shape)
    reach = m[:, 4][None, :] + margin + MARGIN_MPS * ts[:, None]
    reach = np.minimum(reach, gap0[None, :] - CLOSING_M)
    hit = gap < reach
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


def clear_of_static(poses: FloatArray, points: FloatArray, footprint: Footprint) -> bool:
    """No pose's outline nearer a static hit than a margin, or than the robot's is now (a
    robot already that close may move if it gets no closer)."""
    if len(points) == 0:
        return True
    now = float(footprint.clearance(points).min())
    limit = min(STATIC_MARGIN_M, now - 0.005)
    # only what the poses can come near matters
    dist = np.hypot(points[:, 0], points[:, 1])
    far = float(np.hypot(poses[:, 0], poses[:, 1]).max()) + footprint.circumscribed_m + limit
    points = points[dist <= far]
    if len(points) == 0:
        return True
    local = _local(poses, np.broadcast_to(points, (len(poses), *points.shape)))
    return bool(footprint.clearance(local.reshape(-1, 2)).min() >= limit)


@dataclass(frozen=True)
class StopReach:
    """safety_stop's reach (services/controller/safety_stop.py, its params and defaults): a
    robot moving at v is stopped by a hit ahead of its centre, within its footprint radius of
    its line of travel, nearer than radius + ``margin_m`` + v x ``lookahead_s`` + its braking
    distance."""

    margin_m: float = 0.06
    lookahead_s: float = 0.2


def stopped_at(
    poses: FloatArray, points: FloatArray, movers: list[Mover], robot: Robot, reach: StopReach
) -> tuple[float, int | None]:
    """The first time within ``STOPPABLE_S`` at which safety_stop would stop a robot following
    ``poses`` (with their speeds): a hit of the scan where it is (``points``) or a mover's
    outline where it is predicted (its disc, plus the growing margin) inside the reach of the
    speed at that pose, in its direction of travel (inf: none). Judged as safety_stop judges
    a scan: straight ahead (or behind), the footprint radius either side."""
    ts = times()
    sel = np.flatnonzero((ts <= STOPPABLE_S + 1e-9) & (np.abs(poses[:, 3]) > STOP_MOVING_MPS))
    if len(sel) == 0:
        return math.inf, None
    ps, ts = poses[sel], ts[sel]
    radius = robot.footprint_radius_m
    speed = np.abs(ps[:, 3])
    limit = radius + reach.margin_m + STOP_BUFFER_M + speed * reach.lookahead_s
    limit = limit + speed * speed / (2.0 * robot.max_linear_accel_mps2)
    # only what is within the farthest reach of the farthest pose can be hit
    far = float(np.hypot(ps[:, 0], ps[:, 1]).max() + limit.max())
    sets = []
    near = points[np.hypot(points[:, 0], points[:, 1]) <= far] if len(points) else points
    if len(near):
        sets.append(np.broadcast_to(near, (len(ps), *near.shape)))
    if movers:
        m = np.asarray([(k.x, k.y, k.vx, k.vy, k.radius) for k in movers], dtype=np.float64)
        a = np.linspace(0.0, 2.0 * math.pi, OUTLINE_POINTS, endpoint=False)
        r = m[:, 4][None, :, None] + MARGIN_MPS * ts[:, None, None]  # steps x movers x 1
        cx = (m[:, 0][None, :] + m[:, 2][None, :] * ts[:, None])[..., None] + r * np.cos(a)
        cy = (m[:, 1][None, :] + m[:, 3][None, :] * ts[:, None])[..., None] + r * np.sin(a)
        sets.append(np.stack([cx, cy], axis=-1).reshape(len(ps), -1, 2))
    if not sets:
        return math.inf, None
    local = _local(ps, np.concatenate(sets, axis=1))
    along = np.sign(ps[:, 3])[:, None] * local[..., 0]
    dist = np.hypot(local[..., 0], local[..., 1])
    hit = (along > 0.0) & (np.abs(local[..., 1]) <= radius) & (dist <= limit[:, None])
    rows = np.flatnonzero(hit.any(axis=1))
    if len(rows) == 0:
        return math.inf, None
    first = int(np.flatnonzero(hit[rows[0]])[0]) - len(near)  # beyond the hits: a mover's
    return float(ts[rows[0]]), movers[first // OUTLINE_POINTS].track if first >= 0 else None


def choose(
    v0: float,
    w0: float,
    robot: Robot,
    movers: list[Mover],
    points: FloatArray,
    sees_behind: bool,
    ahead: tuple[float, float] = (1.0, 0.0),
    reach: StopReach = StopReach(),
) -> Motion:
    """The evasive motion to recommend. ``ahead``: the unit direction (robot frame) the
    robot is to make progress in (toward its path's carrot; straight ahead without one). Of
    the motions that meet no mover within the horizon: the fastest straight on at a brisk
    speed (``BRISK_SHARE`` of the top or more: a yield on the path), if the robot faces
    within ``ON_COURSE_DEG`` of ``ahead``; else the brisk motion that ends farthest along
    ``ahead`` (past a slow mover's side: waiting for it to cross takes seconds, in other
    movers' way; back toward the path when off it), the gentlest first on a tie; else the
    straightest, then the fastest of the slower ones (down to the stop).
    Then those that meet a mover, the one meeting it latest (then the one whose outline
    would touch it latest: inside the margin already, that still tells the way out; then
    the straighter, then the faster). A motion other than the stop must keep clear of the
    static hits and must not be one safety_stop stops in its first ``STOPPABLE_S``
    (``reach``: its params; the hits and the movers in its swept way): tested in that order
    of preference until one passes (the stop always does)."""
    top, wmax = robot.max_linear_mps, robot.max_angular_rps
    speeds = [s * top for s in SPEEDS] + ([-BACK_SHARE * top] if sees_behind else [])
    judged: list[tuple[Motion, FloatArray]] = []
    for v in speeds:
        for w in [s * wmax for s in TURNS] if v != 0.0 else [0.0]:
            poses = rollout(v0, w0, v, w, robot)
            t, k = ttc(poses, movers, robot.footprint)
            judged.append((Motion(v, w, t, k), poses))
    safe = [mp for mp in judged if math.isinf(mp[0].ttc)]
    brisk = BRISK_SHARE * top
    on_course = math.atan2(abs(ahead[1]), ahead[0]) <= math.radians(ON_COURSE_DEG)

    def preference(mp: tuple[Motion, FloatArray]) -> tuple[float, ...]:
        motion, poses = mp
        if motion.v >= brisk and motion.w == 0.0 and on_course:
            return (0.0, -motion.v)
        if motion.v >= brisk:
            gain = float(poses[-1, 0] * ahead[0] + poses[-1, 1] * ahead[1])
            return (1.0, -round(gain, 3), abs(motion.w))
        return (2.0, abs(motion.w), -motion.v)

    def lateness(mp: tuple[Motion, FloatArray]) -> tuple[float, ...]:
        motion, poses = mp
        touch = ttc(poses, movers, robot.footprint, margin=0.0)[0]
        return (-motion.ttc, -touch, abs(motion.w), -motion.v)

    unsafe = [mp for mp in judged if not math.isinf(mp[0].ttc)]
    order = sorted(safe, key=preference) + sorted(unsafe, key=lateness)
    for motion, poses in order:
        if motion.v == 0.0:
            return motion
        if clear_of_static(poses, points, robot.footprint) and math.isinf(
            stopped_at(poses, points, movers, robot, reach)[0]
        ):
            return motion
    raise AssertionError("unreachable: the stop is among the motions judged")


def expected(
    v0: float, w0: float, robot: Robot, movers: list[Mover], reach: StopReach = StopReach()
) -> Motion:
    """What the robot is about to do without this scenario, judged: the worse of keeping its
    measured velocity and speeding up to its top speed on the same turn (a local controller
    on a clear way does): when it first meets a mover, and when safety_stop would first stop
    it for one (a mover crossing its swept way; the scan's standing hits are the local
    controller's to keep clear of)."""
    worst: Motion | None = None
    empty = np.empty((0, 2))
    for v in (v0, robot.max_linear_mps if v0 >= -0.01 else v0):
        poses = rollout(v0, w0, v, w0, robot)
        t, k = ttc(poses, movers, robot.footprint)
        stop, by = stopped_at(poses, empty, movers, robot, reach)
        motion = Motion(v, w0, t, k, stop, by)
        if worst is None or motion.threat < worst.threat:
            worst = motion
    assert worst is not None
    return worst

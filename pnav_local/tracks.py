"""Obstacles that move, followed from one scan of a robot to the next (the dodge scenario's
eyes; docs/CONTROLLER.md, "dodge").

Per scan: the beams within reach are cut into clusters where neighbouring hits lie apart
(a gap, or a jump in range); a cluster no wider than ``MAX_WIDTH_M`` is an object small
enough to move (a wall is wider: never a candidate), and its centre is estimated as the
middle of its visible arc pushed back by half its width (a cylinder's centre lies behind the
face the lidar sees). Centres go to the world frame with the odometry at the scan (moved on
to the scan's stamp at the measured velocity), and each is matched to the nearest track
predicted to that time, within a gate that grows with the time since the track was seen.
A track's velocity is the least-squares slope of its centres over the last ``WINDOW_S``
of sim time; a track is *moving* once it spans ``MIN_SPAN_S`` with ``MIN_SEEN`` sightings,
its speed is at least ``MOVING_MPS``, its points have left the surface an older scan showed
(``DISPLACED_M``) and its centres lie on the fitted line (``FIT_RMS_M``: a static object's
apparent motion wanders, a body's is steady). A cluster cut by the edge of the lidar's field
or by something nearer in front of it changes shape as the robot moves, so it is matched
but never adds to its track's velocity nor tells whether it left its surface. A moving
track unseen for at most ``COAST_S`` (hidden behind another mover, or merged with it into
one cluster) is still predicted on at its velocity (:meth:`Tracker.movers`). A track told
moving stays moving for ``STICKY_S`` after it last was (a mover turning back at the end of
its line fails the line and the surface tests for a window's length), at the velocity of its
newest ``SHORT_S`` of centres while the whole window's are off a line.

Deterministic (no randomness, ties broken by index) and bounded: at most ``MAX_CLUSTERS``
clusters (the nearest) and ``MAX_TRACKS`` tracks per robot, whatever the scan holds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from common.contract.records import LaserScan, Odometry

FloatArray = npt.NDArray[np.float64]

REACH_M = 6.0  # beams farther than this are not followed
MAX_WIDTH_M = 0.8  # wider clusters are walls or clutter rows: never a mover
MIN_POINTS = 3
SPLIT_M = 0.12  # neighbouring hits farther apart than this (or their beams' spacing x 3)
OCCLUDED_M = 0.1  # a neighbour beam this much nearer hides part of the cluster
MAX_CLUSTERS = 48
MAX_TRACKS = 48
WINDOW_S = 0.5  # the velocity is fitted over this much history
MIN_SPAN_S = 0.2
MIN_SEEN = 4
MOVING_MPS = 0.1  # slower tracks are treated as standing (view changes, noise)
FORGET_S = 0.5  # a track unseen this long is dropped
# a moving track unseen for at most this long (hidden behind another mover, or merged into
# its cluster as two pass close) is still predicted where its velocity takes it
COAST_S = 0.3
# A static object seen from a new place changes shape (a box's faces turn into view), and its
# centre seems to move by up to half a metre a second as the robot passes: so a track also
# has to have left the surface it showed LAG_S ago: the median of its points' distances to
# that scan's points beyond DISPLACED_M (the lidar's noise is 1 mm: 2 cm is far beyond it)...
LAG_S = 0.3
DISPLACED_M = 0.02
# ...and its centres have to lie on a line travelled at constant speed: a static object's
# apparent motion (the centre estimate wandering as faces turn into view) is not steady, a
# body's is (the RMS of the centres about the fitted line within FIT_RMS_M)
FIT_RMS_M = 0.02
HISTORY_S = 0.6
# A mover turning back at the end of its line leaves the constant-velocity fit (its centres
# go out and come back: the RMS grows, the slope falls to nothing) and its points return over
# the surface they left. A track that moved within STICKY_S keeps moving through that, at
# the velocity of its newest SHORT_S of centres when those fit a line (the way it goes now)
# and of the whole window else.
STICKY_S = 0.6
SHORT_S = 0.12
# ...once it was told moving for this long on end: a box told moving for a scan or two as the
# robot passes it (its faces turning into view) is not kept moving
STEADY_S = 0.3
GATE_M = 0.25  # the match gate, plus GATE_MPS x the time since the track was seen
GATE_MPS = 1.5
_RANGE_TOLERANCE_M = 1e-4


@dataclass(frozen=True)
class Cluster:
    """One small object in one scan: its estimated centre (world frame), half its width, the
    beams it spans, and whether its outline is whole (not cut by the field's edge or hidden
    in part by something nearer)."""

    x: float
    y: float
    radius: float
    first: int
    last: int
    whole: bool


@dataclass
class Track:
    """One object followed across scans: its sightings (t, x, y) within the window."""

    id: int
    radius: float
    seen: list[tuple[float, float, float]] = field(default_factory=list)
    last_t: float = 0.0
    prev_t: float = -math.inf  # the sighting before the newest
    last_x: float = 0.0
    last_y: float = 0.0
    vx: float = 0.0
    vy: float = 0.0
    sightings: int = 0
    beams: tuple[int, int] = (0, -1)  # the newest cluster's first and last beam
    displaced: bool = False  # its points left the surface an older scan showed
    fit_rms: float = math.inf  # the centres' RMS distance from the fitted constant velocity
    whole: bool = False  # the newest cluster's outline was all there
    moved_t: float = -math.inf  # the last sighting at which it was told moving (full test)
    told_from: float = math.inf  # the first sighting of the newest run of them told moving

    @property
    def speed(self) -> float:
        return math.hypot(self.vx, self.vy)

    @property
    def told(self) -> bool:
        """Whether this sighting alone tells it moves (the full test)."""
        if self.sightings < MIN_SEEN or len(self.seen) < MIN_SEEN:
            return False
        span = self.seen[-1][0] - self.seen[0][0]
        return (
            span >= MIN_SPAN_S
            and self.speed >= MOVING_MPS
            and self.displaced
            and self.fit_rms <= FIT_RMS_M
        )

    @property
    def moving(self) -> bool:
        """Told moving now, or within ``STICKY_S`` after being told so for ``STEADY_S`` on end
        (turning back, or stopping a moment)."""
        if self.told:
            return True
        steady = self.moved_t - self.told_from >= STEADY_S - 1e-9
        return steady and self.last_t - self.moved_t <= STICKY_S

    def at(self, t: float) -> tuple[float, float]:
        """Where the track is predicted at sim time ``t`` (constant velocity)."""
        dt = t - self.last_t
        return self.last_x + self.vx * dt, self.last_y + self.vy * dt

    def add(self, t: float, c: Cluster) -> None:
        self.prev_t = self.last_t
        self.last_t, self.last_x, self.last_y = t, c.x, c.y
        self.beams = (c.first, c.last)
        self.whole = c.whole
        self.radius = 0.7 * self.radius + 0.3 * c.radius
        self.sightings += 1
        if not c.whole:
            return  # its centre drifts with the view: it tells where, not how fast
        self.seen.append((t, c.x, c.y))
        self.seen = [s for s in self.seen if s[0] >= t - WINDOW_S]
        self._fit()

    def _fit(self) -> None:
        if len(self.seen) < 2:
            return
        a = np.asarray(self.seen, dtype=np.float64)
        ts = a[:, 0] - a[:, 0].mean()
        denom = float(ts @ ts)
        if denom <= 1e-9:
            return
        dx, dy = a[:, 1] - a[:, 1].mean(), a[:, 2] - a[:, 2].mean()
        self.vx = float(ts @ dx) / denom
        self.vy = float(ts @ dy) / denom
        self.fit_rms = float(np.sqrt(np.mean((dx - self.vx * ts) ** 2 + (dy - self.vy * ts) ** 2)))
        if self.fit_rms > FIT_RMS_M:
            short = _line(a[a[:, 0] >= a[-1, 0] - SHORT_S])
            if short is not None and short[2] <= FIT_RMS_M:
                self.vx, self.vy = short[0], short[1]  # the way it goes now


def _line(a: FloatArray) -> tuple[float, float, float] | None:
    """The constant velocity fitted to sightings (t, x, y), and the RMS about it; None for
    fewer than ``MIN_SEEN``."""
    if len(a) < MIN_SEEN:
        return None
    ts = a[:, 0] - a[:, 0].mean()
    denom = float(ts @ ts)
    if denom <= 1e-9:
        return None
    dx, dy = a[:, 1] - a[:, 1].mean(), a[:, 2] - a[:, 2].mean()
    vx, vy = float(ts @ dx) / denom, float(ts @ dy) / denom
    return vx, vy, float(np.sqrt(np.mean((dx - vx * ts) ** 2 + (dy - vy * ts) ** 2)))


def robot_pose(scan: LaserScan, odom: Odometry) -> tuple[float, float, float]:
    """The robot's pose at the scan's stamp: the odometry's, moved on at its velocity."""
    dt = scan.stamp - odom.stamp
    yaw = odom.yaw + odom.angular_rps * dt
    mid = odom.yaw + odom.angular_rps * dt / 2.0
    d = odom.linear_mps * dt
    return odom.x + d * math.cos(mid), odom.y + d * math.sin(mid), yaw


def clusters(scan: LaserScan, pose: tuple[float, float, float]) -> list[Cluster]:
    """The scan's small objects (at most ``MAX_CLUSTERS``, the nearest), world frame."""
    ranges = scan.ranges.astype(np.float64)
    n = len(ranges)
    angles = scan.angles()
    valid = (
        np.isfinite(ranges)
        & (ranges >= scan.range_min - _RANGE_TOLERANCE_M)
        & (ranges <= min(scan.range_max, REACH_M))
    )
    idx = np.flatnonzero(valid)
    if len(idx) < MIN_POINTS:
        return []
    r, a = ranges[idx], angles[idx]
    px, py = r * np.cos(a), r * np.sin(a)
    step = np.hypot(np.diff(px), np.diff(py))
    spacing = 3.0 * abs(scan.angle_increment) * np.maximum(r[:-1], r[1:])
    cut = (np.diff(idx) > 1) | (step > np.maximum(SPLIT_M, spacing))
    starts = np.concatenate(([0], np.flatnonzero(cut) + 1))
    ends = np.concatenate((starts[1:], [len(idx)]))
    full_turn = abs(abs(scan.angle_increment) * n - 2.0 * math.pi) < 1e-6
    found: list[tuple[float, Cluster]] = []
    ox, oy, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    for lo, hi in zip(starts.tolist(), ends.tolist(), strict=True):
        if hi - lo < MIN_POINTS:
            continue
        width = math.hypot(px[hi - 1] - px[lo], py[hi - 1] - py[lo])
        if width > MAX_WIDTH_M:
            continue
        mx, my = float(px[lo:hi].mean()), float(py[lo:hi].mean())
        dist = math.hypot(mx, my)
        half = width / 2.0
        # the face seen lies in front of the centre: push back along the line of sight
        cx, cy = mx + half * mx / dist, my + half * my / dist
        first, last = int(idx[lo]), int(idx[hi - 1])
        whole = _whole(ranges, valid, first, last, n, full_turn)
        found.append(
            (dist, Cluster(ox + c * cx - s * cy, oy + s * cx + c * cy, half, first, last, whole))
        )
    found.sort(key=lambda dc: dc[0])
    return [cl for _, cl in found[:MAX_CLUSTERS]]


def world_points(scan: LaserScan, pose: tuple[float, float, float]) -> FloatArray:
    """Every beam's hit in the world frame (n x 2; NaN where the beam has none within
    reach)."""
    ranges = scan.ranges.astype(np.float64)
    ok = (
        np.isfinite(ranges)
        & (ranges >= scan.range_min - _RANGE_TOLERANCE_M)
        & (ranges <= min(scan.range_max, REACH_M))
    )
    a = scan.angles() + pose[2]
    r = np.where(ok, ranges, np.nan)
    return np.column_stack([pose[0] + r * np.cos(a), pose[1] + r * np.sin(a)])


def _whole(
    ranges: FloatArray, valid: npt.NDArray[np.bool_], first: int, last: int, n: int, wrap: bool
) -> bool:
    """Whether a cluster's outline is all there: neither end at the edge of the lidar's
    field, nor beside a nearer hit that may hide part of it."""
    for end, beside in ((first, first - 1), (last, last + 1)):
        if wrap:
            beside %= n
        elif beside < 0 or beside >= n:
            return False
        if valid[beside] and ranges[beside] < ranges[end] - OCCLUDED_M:
            return False
    return True


@dataclass
class Tracker:
    """One robot's tracks, updated scan by scan (kept in the scenario's memory)."""

    tracks: list[Track] = field(default_factory=list)
    next_id: int = 1
    last_t: float | None = None
    period_s: float = 0.0  # the time between the last two scans seen
    # recent scans' hits in the world frame (t, n x 2), the newest last, HISTORY_S of them
    history: list[tuple[float, FloatArray]] = field(default_factory=list)

    def update(self, scan: LaserScan, odom: Odometry) -> list[Cluster]:
        """Match the scan's clusters to the tracks; returns the clusters."""
        t = scan.stamp
        if t == self.last_t:
            return []  # the same scan again (a silent scenario is asked once per activation)
        if self.last_t is not None and t < self.last_t:
            self.tracks, self.last_t = [], None  # sim time went back: a new run
        if self.last_t is not None:
            self.period_s = t - self.last_t
        self.last_t = t
        pose = robot_pose(scan, odom)
        found = clusters(scan, pose)
        world = world_points(scan, pose)
        self.tracks = [k for k in self.tracks if t - k.last_t <= FORGET_S]
        pairs: list[tuple[float, int, int]] = []
        for i, k in enumerate(self.tracks):
            px, py = k.at(t)
            gate = GATE_M + GATE_MPS * (t - k.last_t)
            for j, cl in enumerate(found):
                d = math.hypot(cl.x - px, cl.y - py)
                if d <= gate:
                    pairs.append((d, i, j))
        pairs.sort()
        used_t: set[int] = set()
        used_c: set[int] = set()
        for _, i, j in pairs:
            if i in used_t or j in used_c:
                continue
            used_t.add(i)
            used_c.add(j)
            self.tracks[i].add(t, found[j])
        for j, cl in enumerate(found):
            if j in used_c or len(self.tracks) >= MAX_TRACKS:
                continue
            k = Track(self.next_id, cl.radius)
            self.next_id += 1
            k.add(t, cl)
            self.tracks.append(k)
        self._displacement(t, world)
        self._told(t)
        self.history = [h for h in self.history if h[0] >= t - HISTORY_S]
        self.history.append((t, world[np.isfinite(world[:, 0])]))
        return found

    def _told(self, t: float) -> None:
        """Note when each track seen now was last told moving (its stickiness)."""
        for k in self.tracks:
            if k.last_t != t or not k.told:
                continue
            if k.moved_t < k.prev_t:  # not told at its previous sighting: a new run
                k.told_from = t
            k.moved_t = t

    def _displacement(self, t: float, world: FloatArray) -> None:
        """For each track seen now and fast enough: whether its points left the surface the
        scan of LAG_S ago showed there (a static object's points lie on it)."""
        old = [h for h in self.history if h[0] <= t - LAG_S]
        if not old:
            return
        ref = old[-1][1]
        for k in self.tracks:
            # a cut outline changes as the view does: its points prove nothing either way
            if k.last_t != t or k.speed < MOVING_MPS or not k.whole:
                continue
            pts = world[k.beams[0] : k.beams[1] + 1]
            pts = pts[np.isfinite(pts[:, 0])]
            if len(pts) == 0:
                continue
            lo, hi = pts.min(axis=0) - 0.5, pts.max(axis=0) + 0.5
            near = ref[np.all((ref >= lo) & (ref <= hi), axis=1)]
            if len(near) == 0:
                k.displaced = True  # nothing was there
                continue
            d = np.hypot(pts[:, 0:1] - near[None, :, 0], pts[:, 1:2] - near[None, :, 1])
            k.displaced = bool(np.median(d.min(axis=1)) > DISPLACED_M)

    def moving(self) -> list[Track]:
        """The tracks that move, seen in the newest scan."""
        return [k for k in self.tracks if k.moving and k.last_t == self.last_t]

    def movers(self) -> list[Track]:
        """The tracks that move, seen in the newest scan or unseen for at most ``COAST_S``
        (a mover hidden for a moment is still there): :meth:`Track.at` says where."""
        if self.last_t is None:
            return []
        return [k for k in self.tracks if k.moving and self.last_t - k.last_t <= COAST_S]

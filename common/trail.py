"""Where the robot has just been: its own recent poses, as evidence that the space its
footprint swept there is free.

A lidar that does not see behind the robot (the Jackal's 270 degrees) cannot say the way
back is clear, so nothing backed up blind, and a box robot that had driven into a pocket it
could not turn in stood there until its goal failed (the BARN-protocol hard worlds: every
turn blocked by a corner, every arc forward blocked). But the robot drove in: every point
its outline covered on the way, in the last TRAIL_S seconds, was free then. In a world whose
obstacles stay put, backing out along the same poses meets nothing; recovery retraces them
(:meth:`Trail.retrace_turn`), and safety_stop lets a blind reverse on that trail pass
(:meth:`Trail.covers`) where it stops any other.

Only outline points are tested (every SAMPLE_M along the footprint's edges at poses
SAMPLE_M apart along the motion): a point counts as covered within COVER_TOLERANCE_M of
some pose's outline, the trail's poses interpolated FILL_M and FILL_RAD apart (the robot
swept between two odometry readings too: a box turning as it went left notches between
its outlines a tenth of a second apart, 7 mm deep at a corner). Poses are kept at least
KEEP_STEP_M or KEEP_TURN_RAD apart, at most MAX_POSES and TRAIL_S seconds of sim time old
(a moving obstacle may have stepped in since: the memory is short, and backing up is slow).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from common.footprint import Footprint

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

TRAIL_S = 30.0  # sim s: older poses are not evidence of free space
MAX_POSES = 300
KEEP_STEP_M = 0.02  # a pose is kept when this far from the last kept one
KEEP_TURN_RAD = math.radians(5.0)  # ... or turned this much
SAMPLE_M = 0.03  # outline points and motion poses tested this far apart
# how far outside every past outline a point may lie: what odometry, the interpolation and
# a pure-pursuit arc against the trail's own curves leave (3 to 7 mm backing 0.3 m out of
# barn_hard_001's gap); the bridge's safety layer lets a turning corner come as near a
# return (common.sweep.TURN_MARGIN_M)
COVER_TOLERANCE_M = 0.01
MAX_TURN_PER_M = 10.0  # the hardest curvature a retrace asks for (1.5 rad/s at 0.15 m/s)
FILL_M = 0.01  # the trail's poses interpolated this close together when testing
FILL_RAD = math.radians(1.0)
PAIRS_AT_ONCE = 1 << 15  # point x pose pairs tested at once (bounded memory)

Pose = tuple[float, float, float, float]  # (stamp, x, y, yaw), world frame


@dataclass
class Trail:
    """The robot's recent poses (odometry), oldest first."""

    poses: deque[Pose] = field(default_factory=lambda: deque(maxlen=MAX_POSES))
    last: Pose | None = None  # the pose noted last, kept or not

    def note(self, stamp: float, x: float, y: float, yaw: float) -> None:
        """Keep this pose if it is far enough from the last one kept and the robot did not
        get here backing up (then it is on the trail already, and the way back stays as it
        was); a stamp going back (the sim restarted) starts afresh."""
        poses, before = self.poses, self.last
        self.last = (stamp, x, y, yaw)
        if poses and stamp < poses[-1][0] - 1.0:
            poses.clear()
            before = None
        if before is not None:
            _, bx, by, byaw = before
            if (x - bx) * math.cos(byaw) + (y - by) * math.sin(byaw) < -1e-3:
                return
        if poses:
            _, lx, ly, lyaw = poses[-1]
            turned = abs(math.atan2(math.sin(yaw - lyaw), math.cos(yaw - lyaw)))
            if math.hypot(x - lx, y - ly) < KEEP_STEP_M and turned < KEEP_TURN_RAD:
                return
        poses.append((stamp, x, y, yaw))
        while poses and poses[-1][0] - poses[0][0] > TRAIL_S:
            poses.popleft()

    def covers(
        self,
        footprint: Footprint,
        pose: tuple[float, float, float],
        linear: float,
        angular: float,
        distance_m: float,
    ) -> bool:
        """Whether the footprint moving from ``pose`` (world) at ``(linear, angular)`` for
        ``distance_m`` of travel keeps every point of its outline within what its outline
        covered at the trail's poses (or at ``pose`` itself)."""
        if not self.poses or linear == 0.0:
            return False
        reach = 2.0 * footprint.circumscribed_m + distance_m
        kept = _filled(
            np.array([p[1:] for p in self.poses] + [pose], dtype=np.float64), pose, reach
        )
        steps = max(1, math.ceil(distance_m / SAMPLE_M))
        s = np.arange(1, steps + 1) * (distance_m / steps) * math.copysign(1.0, linear)
        turn_per_m = angular / linear
        x0, y0, yaw0 = pose
        yaw = yaw0 + turn_per_m * s
        if abs(turn_per_m) > 1e-9:
            lx = np.sin(turn_per_m * s) / turn_per_m
            ly = (1.0 - np.cos(turn_per_m * s)) / turn_per_m
        else:
            lx, ly = s, np.zeros_like(s)
        c0, s0 = math.cos(yaw0), math.sin(yaw0)
        xs, ys = x0 + c0 * lx - s0 * ly, y0 + s0 * lx + c0 * ly
        points = _outline_points(footprint)
        c, sn = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
        wx = (xs[:, None] + c * points[None, :, 0] - sn * points[None, :, 1]).ravel()
        wy = (ys[:, None] + sn * points[None, :, 0] + c * points[None, :, 1]).ravel()
        # the robot's own pose first (most of the outline backs into it), then every other
        # pose at once, PAIRS_AT_ONCE point x pose pairs at a time
        left = ~_inside(footprint, kept[:1], wx, wy)[0]
        todo = np.flatnonzero(left)
        rest = kept[1:]
        if len(todo) and len(rest):
            rows = max(1, PAIRS_AT_ONCE // len(todo))
            for i in range(0, len(rest), rows):
                inside = _inside(footprint, rest[i : i + rows], wx[todo], wy[todo]).any(axis=0)
                todo = todo[~inside]
                if not len(todo):
                    break
        return not len(todo)

    def retrace_turn(self, pose: tuple[float, float, float], back_m: float) -> float | None:
        """The curvature (rad per m) that backs the robot at ``pose`` toward the trail's
        pose ``back_m`` behind along it (pure pursuit, in reverse); None if the trail does
        not reach that far behind the robot."""
        x, y, yaw = pose
        poses = list(self.poses)
        if not poses:
            return None
        # from the trail's pose nearest the robot (a robot backing up is behind the newest)
        near = min(range(len(poses)), key=lambda i: math.hypot(poses[i][1] - x, poses[i][2] - y))
        walked, last = 0.0, (x, y)
        target = None
        for _, px, py, _ in reversed(poses[: near + 1]):
            walked += math.hypot(px - last[0], py - last[1])
            last = (px, py)
            if walked >= back_m:
                target = (px, py)
                break
        if target is None:
            return None
        dx, dy = target[0] - x, target[1] - y
        tx = math.cos(yaw) * dx + math.sin(yaw) * dy
        ty = -math.sin(yaw) * dx + math.cos(yaw) * dy
        if tx >= 0.0:
            return None  # the trail behind is not behind the robot: no reverse follows it
        return 2.0 * ty / max(tx * tx + ty * ty, 1e-9)

    def turn_behind(self, pose: tuple[float, float, float], back_m: float) -> float | None:
        """The curvature (rad per m) the trail itself took over its last ``back_m`` up to
        the pose nearest ``pose``: its heading change over the distance covered (a robot
        that turned as it crept keeps to it backing at that rate, where an arc toward a pose
        farther back cuts across); at most MAX_TURN_PER_M either way. None without a pose
        that far back."""
        x, y, _ = pose
        poses = list(self.poses)
        if not poses:
            return None
        near = min(range(len(poses)), key=lambda i: math.hypot(poses[i][1] - x, poses[i][2] - y))
        walked, turned = 0.0, 0.0
        for a, b in zip(reversed(poses[:near]), reversed(poses[1 : near + 1]), strict=True):
            walked += math.hypot(b[1] - a[1], b[2] - a[2])
            turned += math.atan2(math.sin(b[3] - a[3]), math.cos(b[3] - a[3]))
            if walked >= back_m:
                return max(-MAX_TURN_PER_M, min(MAX_TURN_PER_M, turned / walked))
        return None


def _filled(poses: FloatArray, pose: tuple[float, float, float], reach_m: float) -> FloatArray:
    """The poses (x, y, yaw; oldest first) within ``reach_m`` of ``pose``, with poses
    interpolated between each two at most FILL_M and FILL_RAD apart; ``poses``' last (the
    robot's own) first."""
    near = np.hypot(poses[:, 0] - pose[0], poses[:, 1] - pose[1]) <= reach_m
    both = np.flatnonzero(near[:-1] & near[1:])
    a, b = poses[both], poses[both + 1]
    turn = np.arctan2(np.sin(b[:, 2] - a[:, 2]), np.cos(b[:, 2] - a[:, 2]))
    step = np.hypot(b[:, 0] - a[:, 0], b[:, 1] - a[:, 1])
    n = np.maximum(1, np.ceil(np.maximum(step / FILL_M, np.abs(turn) / FILL_RAD))).astype(np.int64)
    pair = np.repeat(np.arange(len(both)), n)
    f = (np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)) / n[pair]
    d = np.column_stack([b[:, 0] - a[:, 0], b[:, 1] - a[:, 1], turn])[pair]
    filled: FloatArray = np.vstack([poses[-1:], a[pair] + f[:, None] * d])
    return filled


def _inside(footprint: Footprint, poses: FloatArray, wx: FloatArray, wy: FloatArray) -> BoolArray:
    """[pose, point]: whether each world point lies within COVER_TOLERANCE_M of the outline
    placed at each pose (or inside it)."""
    dx = wx[None, :] - poses[:, 0:1]
    dy = wy[None, :] - poses[:, 1:2]
    c, s = np.cos(poses[:, 2:3]), np.sin(poses[:, 2:3])
    lx, ly = c * dx + s * dy, -s * dx + c * dy
    box = _box(footprint)
    if box is not None:
        # a rectangle along the robot's axes (the Jackal's) in closed form: the general
        # outline distance was most of a recovery step's time
        cx, cy, hx, hy = box
        ex = np.maximum(np.abs(lx - cx) - hx, 0.0)
        ey = np.maximum(np.abs(ly - cy) - hy, 0.0)
        near: BoolArray = ex * ex + ey * ey <= COVER_TOLERANCE_M * COVER_TOLERANCE_M
        return near
    local = np.stack([lx.ravel(), ly.ravel()], axis=1)
    out: BoolArray = (footprint.clearance(local) <= COVER_TOLERANCE_M).reshape(dx.shape)
    return out


def _box(footprint: Footprint) -> tuple[float, float, float, float] | None:
    """(centre x, centre y, half length, half width) of a rectangular footprint with sides
    along the robot's axes; None for any other outline."""
    v = footprint.vertices
    if footprint.is_disc or len(v) != 4:
        return None
    lo, hi = v.min(axis=0), v.max(axis=0)
    corners = {(bool(x == hi[0]), bool(y == hi[1])) for x, y in v}
    on_x = np.isin(v[:, 0], (lo[0], hi[0])).all()
    on_y = np.isin(v[:, 1], (lo[1], hi[1])).all()
    if not (on_x and on_y) or len(corners) != 4:
        return None
    return (
        float(lo[0] + hi[0]) / 2.0,
        float(lo[1] + hi[1]) / 2.0,
        float(hi[0] - lo[0]) / 2.0,
        float(hi[1] - lo[1]) / 2.0,
    )


def _outline_points(footprint: Footprint) -> FloatArray:
    """Points every SAMPLE_M along the footprint's outline (robot frame)."""
    v = footprint.vertices
    out = []
    for a, b in zip(v, np.roll(v, -1, axis=0), strict=True):
        n = max(1, math.ceil(float(np.hypot(*(b - a))) / SAMPLE_M))
        out.append(a[None, :] + np.linspace(0.0, 1.0, n, endpoint=False)[:, None] * (b - a))
    points: FloatArray = np.vstack(out)
    return points

"""The lidar obstacle layer: what the map does not show, seen by the robot's laser.

Nav2 calls this an obstacle layer: hits of the newest scan that are farther than UNMAPPED_M
from every obstacle of the map are placed in the world with the robot's pose at the scan's
stamp (interpolated between the odometry rows around it), and the route is planned around
them (routes.py) rather than through a pallet or a crate for the controllers to fight over.

Obstacles are remembered for SEEN_MEMORY_S after the lidar last saw them, and forgotten
sooner when a beam of a newer scan passes beyond them (the place is free: the obstacle
moved, or was a pose error). Without the memory, a lidar that does not see all round (the
Jackal's 270 degrees) made whatever lay behind the robot look free: the planner re-planned
through it, the robot turned, saw it, and re-planned back, circling on the spot. The memory
is long (the field seen so far, not the last few seconds) and reaches SEEN_RANGE_M: with a
few seconds and 2.5 m, in a cluttered field the planner forgot the dead end it had just
left and planned back into it (the BARN-protocol hard worlds).

A hit is the surface of something beyond it: it is placed half a planning cell farther
along its beam (SURFACE_PUSH_CELLS), in the cell behind the surface. Placed where measured,
a hit on a surface lying on a cell boundary fell into the free cell in front of it half the
time, and the inflation grown from that cell's centre closed gaps the robot fits through
(a 0.6 m gap for a 0.27 m inflation).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from common.contract import records

SEEN_RANGE_M = 4.0  # lidar hits farther than this are not used (pose error grows with range)
UNMAPPED_M = 0.15  # a hit farther than this from every mapped obstacle is an unmapped one
SEEN_MAX_AGE_S = 1.0  # sim s: with no scan this recent, no obstacle is planned around
SEEN_MEMORY_S = 120.0  # sim s: an obstacle no beam has seen since then is forgotten
CLEAR_MARGIN_M = 0.1  # a beam this much beyond a remembered obstacle clears it
MAX_REMEMBERED = 20000  # points kept per robot at most (the newest), one per planning cell
SURFACE_PUSH_CELLS = 0.5  # a hit is placed this many planning cells beyond the measured range
POSE_MATCH_S = 0.05  # the scan's pose: odometry within this (sim s) of the scan's stamp
POSES_KEPT = 90  # odometry poses remembered per robot (3 s at 30 Hz)
OBSTACLE_BUCKET_M = 0.1  # obstacles within about this of one planned around are not new

Pose = tuple[float, float, float, float]  # (stamp, x, y, yaw)
Points = np.ndarray[Any, np.dtype[np.float64]]

NO_POINTS: Points = np.zeros((0, 2))


@dataclass(frozen=True)
class Seen:
    """The unmapped obstacles known after one laser scan: its hits farther than UNMAPPED_M
    from every obstacle of the map, and those remembered from earlier scans, in the world
    frame (an (n, 2) array; ``seen_at``: when the lidar last saw each, sim s)."""

    scan_id: int
    stamp: float
    points: Points
    seen_at: np.ndarray[Any, np.dtype[np.float64]] = field(default_factory=lambda: np.zeros(0))


@dataclass
class PoseTrail:
    """The robot's recent odometry poses, to place a scan with the pose at its stamp."""

    poses: deque[Pose] = field(default_factory=lambda: deque(maxlen=POSES_KEPT))

    def note(self, odom: records.Odometry) -> None:
        poses = self.poses
        if not poses or odom.stamp > poses[-1][0]:
            poses.append((odom.stamp, odom.x, odom.y, odom.yaw))
        elif odom.stamp < poses[-1][0] - 1.0:  # sim time went back: the sim restarted
            poses.clear()
            poses.append((odom.stamp, odom.x, odom.y, odom.yaw))

    def at(self, stamp: float) -> tuple[float, float, float] | None:
        """The robot's pose at sim time ``stamp``, interpolated between the odometry rows
        around it; None if no row is within POSE_MATCH_S of it."""
        before = after = None
        for pose in reversed(self.poses):
            if pose[0] <= stamp:
                before = pose
                break
            after = pose
        if before is not None and after is not None and after[0] - before[0] <= 2 * POSE_MATCH_S:
            f = (stamp - before[0]) / max(after[0] - before[0], 1e-9)
            turn = math.atan2(math.sin(after[3] - before[3]), math.cos(after[3] - before[3]))
            return (
                before[1] + f * (after[1] - before[1]),
                before[2] + f * (after[2] - before[2]),
                before[3] + f * turn,
            )
        near = [p for p in (before, after) if p is not None and abs(p[0] - stamp) <= POSE_MATCH_S]
        if not near:
            return None
        best = min(near, key=lambda p: abs(p[0] - stamp))
        return best[1], best[2], best[3]


def one_per_cell(points: Points, cell_m: float) -> Points:
    """The first of ``points`` in each ``cell_m`` square: the planner blocks cells, and a
    long memory of every beam's hit would fill MAX_REMEMBERED with duplicates."""
    if len(points) < 2:
        return points
    cells = np.floor(points / cell_m).astype(np.int64)
    _, first = np.unique(cells[:, 0] * 1_000_003 + cells[:, 1], return_index=True)
    kept: Points = points[np.sort(first)]
    return kept


def _bucket_keys(points: Points) -> np.ndarray[Any, np.dtype[np.int64]]:
    cells = np.floor(points / OBSTACLE_BUCKET_M).astype(np.int64)
    return cells[:, 0] * 1_000_003 + cells[:, 1]


def remembered(
    before: Seen | None,
    scan: records.LaserScan,
    pose: tuple[float, float, float],
    hits: Points,
) -> tuple[Points, np.ndarray[Any, np.dtype[np.float64]]]:
    """The obstacles of ``before`` still worth planning around after ``scan``, and when each
    was last seen: seen within SEEN_MEMORY_S, not where a new hit is (that one is newer), and
    not cleared by ``scan``: a beam towards it, within SEEN_RANGE_M, reaching CLEAR_MARGIN_M
    past it. An obstacle outside the lidar's field of view is kept: unseen is not free."""
    if before is None or not len(before.points) or before.stamp > scan.stamp:
        return NO_POINTS, np.zeros(0)  # nothing yet, or sim time went back: a new run
    keep = scan.stamp - before.seen_at <= SEEN_MEMORY_S
    points = before.points
    if len(hits):
        keep &= ~np.isin(_bucket_keys(points), _bucket_keys(hits))
    x, y, yaw = pose
    dx, dy = points[:, 0] - x, points[:, 1] - y
    dist = np.hypot(dx, dy)
    bearing = np.arctan2(dy, dx) - yaw - scan.angle_min
    bearing = np.mod(bearing, 2.0 * math.pi)
    n = len(scan.ranges)
    beam = np.rint(bearing / scan.angle_increment).astype(np.int64) if n else bearing
    in_view = (beam >= 0) & (beam < n) & (dist <= SEEN_RANGE_M)
    if in_view.any():
        ranges = np.asarray(scan.ranges, dtype=np.float64)
        reach = np.where(in_view, ranges[np.clip(beam, 0, max(n - 1, 0))], np.nan)
        with np.errstate(invalid="ignore"):
            # inf: the beam met nothing; NaN (no reading) clears nothing
            cleared = in_view & (np.isposinf(reach) | (reach > dist + CLEAR_MARGIN_M))
        keep &= ~cleared
    return points[keep], before.seen_at[keep]


def recent(seen: Seen | None, now: float | None) -> Points:
    """The unmapped obstacles to plan around: the newest scan's, unless it is stale."""
    if seen is None or (now is not None and now - seen.stamp > SEEN_MAX_AGE_S):
        return NO_POINTS
    return seen.points


def bucket(x: float, y: float) -> tuple[int, int]:
    return math.floor(x / OBSTACLE_BUCKET_M), math.floor(y / OBSTACLE_BUCKET_M)


def buckets(points: Points) -> set[tuple[int, int]]:
    return {bucket(float(px), float(py)) for px, py in points}


def known(avoided: set[tuple[int, int]], x: float, y: float) -> bool:
    """Whether (x, y) is within a bucket of an obstacle the route was planned around."""
    bx, by = bucket(x, y)
    return any((bx + i, by + j) in avoided for i in (-1, 0, 1) for j in (-1, 0, 1))

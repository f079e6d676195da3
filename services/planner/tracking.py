"""Following a path: where the robot is along it, where to steer, how far is left.

A route is a polyline from where the robot was when it was planned to the target. The
follower keeps the index of the segment the robot is on and only ever searches forward from
it, so a path that doubles back near itself cannot make the robot skip half of it.

The steering point is ``lookahead_m`` ahead of the robot's projection on its segment, but
never past the segment's end vertex: after the line-of-sight shortcut those vertices are
where the path bends around an inflated obstacle, and cutting the corner there would take
the robot through the inflation margin. Within ``switch_m`` of the vertex the follower moves
on to the next segment.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from services.planner.path import XY

LOOKAHEAD_M = 0.35
SWITCH_M = 0.08


def wrap_angle(angle: float) -> float:
    """``angle`` wrapped to (-pi, pi]."""
    wrapped = math.atan2(math.sin(angle), math.cos(angle))
    return math.pi if wrapped == -math.pi else wrapped


def heading_error(x: float, y: float, yaw: float, point: XY) -> float:
    """Angle to turn (counter-clockwise positive) to face ``point`` from pose (x, y, yaw)."""
    return wrap_angle(math.atan2(point[1] - y, point[0] - x) - yaw)


@dataclass
class Route:
    """A path to one target on one version of the map (None: no map, a straight line)."""

    target_key: tuple[Any, ...]
    map_version: str | None
    points: np.ndarray[Any, np.dtype[np.float64]]
    planned: bool  # False: a straight line (no map, or no path found on it)
    segment: int = 0
    made_at: float = field(default_factory=time.monotonic)
    made_stamp: float = 0.0  # sim time it was planned at
    # The unmapped obstacles (lidar hits) it was planned around, as OBSTACLE_BUCKET_M buckets,
    # and the newest scan checked against it: only new obstacles near it call for a new plan.
    avoided: set[tuple[int, int]] = field(default_factory=set)
    checked_scan: int | None = None
    # Why the map proves the target cannot be reached (reachability.py); None: it may be.
    unreachable: str | None = None

    @classmethod
    def of(
        cls, target_key: tuple[Any, ...], map_version: str | None, points: list[XY], planned: bool
    ) -> Route:
        return cls(target_key, map_version, np.asarray(points, dtype=np.float64), planned)

    @property
    def waypoints(self) -> int:
        """Vertices after the start: the turns and the target."""
        return len(self.points) - 1

    def clearance_ahead(
        self, x: float, y: float, obstacles: np.ndarray[Any, np.dtype[np.float64]]
    ) -> np.ndarray[Any, np.dtype[np.float64]]:
        """Per obstacle point, its distance to what is left of the route: from the robot at
        (x, y) to the current segment's end vertex, then on along the route."""
        ahead = np.vstack([[x, y], self.points[self.segment + 1 :]])
        best = np.full(len(obstacles), math.inf)
        for a, b in itertools.pairwise(ahead):
            ab = b - a
            length2 = float(ab @ ab)
            rel = obstacles - a
            t = np.clip(rel @ ab / length2, 0.0, 1.0) if length2 > 1e-12 else np.zeros(len(rel))
            gap = rel - t[:, None] * ab
            np.minimum(best, np.hypot(gap[:, 0], gap[:, 1]), out=best)
        return best


@dataclass(frozen=True)
class Progress:
    lookahead: XY  # where to steer now
    waypoint: int  # 1-based index of the vertex the robot is heading for
    waypoints: int  # how many vertices there are after the start
    remaining_m: float  # from the robot, back onto the path, along it to the target
    deviation_m: float  # distance from the robot to the path
    unreachable: str | None = None  # the route's: why the map proves the target unreachable


def _project(a: XY, b: XY, x: float, y: float) -> tuple[float, float, float]:
    """Projection of (x, y) on segment a-b: (qx, qy, t) with t in [0, 1] unless beyond b."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    length2 = dx * dx + dy * dy
    t = ((x - a[0]) * dx + (y - a[1]) * dy) / length2 if length2 > 1e-12 else 1.0
    tc = min(1.0, max(0.0, t))
    return a[0] + dx * tc, a[1] + dy * tc, t


def follow(
    route: Route, x: float, y: float, lookahead_m: float = LOOKAHEAD_M, switch_m: float = SWITCH_M
) -> Progress:
    """Advance ``route.segment`` to where the robot (x, y) is; return where to steer."""
    pts = route.points
    last = len(pts) - 2  # index of the final segment
    k = min(route.segment, last)
    a, b = pts[k:-1], pts[k + 1 :]
    ab = b - a
    lengths2 = np.einsum("ij,ij->i", ab, ab)
    rel = np.array([x, y]) - a
    t = np.clip(np.einsum("ij,ij->i", rel, ab) / np.maximum(lengths2, 1e-12), 0.0, 1.0)
    proj = a + ab * t[:, None]
    dist = np.hypot(proj[:, 0] - x, proj[:, 1] - y)
    seg = k + int(np.argmin(dist))
    deviation = float(dist[seg - k])
    qx, qy, t_seg = _project(tuple(pts[seg]), tuple(pts[seg + 1]), x, y)
    # Move on once the robot is at the segment's end vertex, or already past it: the nearest
    # segment alone cannot tell "just before the corner" from "just after it".
    while seg < last and (
        t_seg >= 1.0 or math.hypot(pts[seg + 1, 0] - x, pts[seg + 1, 1] - y) < switch_m
    ):
        seg += 1
        qx, qy, t_seg = _project(tuple(pts[seg]), tuple(pts[seg + 1]), x, y)
    route.segment = seg
    ex, ey = float(pts[seg + 1, 0]), float(pts[seg + 1, 1])
    to_end = math.hypot(ex - qx, ey - qy)
    if to_end <= lookahead_m:
        look = (ex, ey)
    else:
        f = lookahead_m / to_end
        look = (qx + (ex - qx) * f, qy + (ey - qy) * f)
    later = pts[seg + 1 :]
    along = float(np.hypot(*np.diff(later, axis=0).T).sum()) if len(later) > 1 else 0.0
    return Progress(
        lookahead=look,
        waypoint=seg + 1,
        waypoints=route.waypoints,
        remaining_m=deviation + to_end + along,
        deviation_m=deviation,
        unreachable=route.unreachable,
    )

"""A robot's footprint: the disc of its radius, or a polygon in its own frame.

A footprint polygon lists its vertices in metres in the robot's frame (x forward, y left),
counter-clockwise, with the robot's centre strictly inside; the robot row stores it in
``robot.footprint_polygon`` (CONTRACT.md) and a model file in ``footprint_polygon``
(docs/SIM.md, "Robot models"). Without one, the footprint is the disc of
``footprint_radius_m``, as it always was.

Every user needs the same few figures and tests, so they live here once:

- :attr:`Footprint.inscribed_m` (the largest disc round the centre inside the footprint) and
  :attr:`Footprint.circumscribed_m` (the smallest round the centre containing it): a planner
  that does not know the heading must keep the circumscribed radius clear, one that does may
  start from the inscribed one;
- :meth:`Footprint.at` (the polygon at a pose, world frame), :meth:`Footprint.clearance`
  (signed distance from points in the robot's frame to the outline: negative inside) and
  :meth:`Footprint.travel_m` (how far the robot goes straight before its outline meets a point);
- common/collision.py: the footprint at a pose against an occupancy grid or a scan's points
  (the planner's path check, the sim's tests and local planners use them, so they agree on
  what touches).

:func:`polygon_problem` is the one validation (the robot table's CHECKs say the same in SQL):
at most ``MAX_VERTICES`` vertices, finite, within ``MAX_COORD_M``, simple (no two edges cross
or touch but neighbours at their shared vertex), counter-clockwise, and containing the centre
with some room (``MIN_CENTRE_ROOM_M``).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
Polygon = tuple[tuple[float, float], ...]

MIN_VERTICES = 3
MAX_VERTICES = 64  # the robot table's bound: a CHECK costs O(n^2) and no body needs more
MAX_COORD_M = 5.0  # a vertex within 5 m of the centre: a ground robot 10 m across
MIN_CENTRE_ROOM_M = 0.001  # the centre at least 1 mm inside the outline
# the default step between the headings checked while a robot turns in place
TURN_STEP_RAD = math.radians(15.0)


def _cross(ax: float, ay: float, bx: float, by: float) -> float:
    return ax * by - ay * bx


def _orient(p: Sequence[float], q: Sequence[float], r: Sequence[float]) -> float:
    return _cross(q[0] - p[0], q[1] - p[1], r[0] - p[0], r[1] - p[1])


def _on_segment(p: Sequence[float], q: Sequence[float], r: Sequence[float]) -> bool:
    # r collinear with p-q: within its bounding box
    return min(p[0], q[0]) <= r[0] <= max(p[0], q[0]) and min(p[1], q[1]) <= r[1] <= max(p[1], q[1])


def segments_meet(
    a: Sequence[float], b: Sequence[float], c: Sequence[float], d: Sequence[float]
) -> bool:
    """Whether segments a-b and c-d share a point (crossing, touching or overlapping)."""
    o1, o2, o3, o4 = _orient(a, b, c), _orient(a, b, d), _orient(c, d, a), _orient(c, d, b)
    if ((o1 > 0 and o2 < 0) or (o1 < 0 and o2 > 0)) and (
        (o3 > 0 and o4 < 0) or (o3 < 0 and o4 > 0)
    ):
        return True
    return (
        (o1 == 0 and _on_segment(a, b, c))
        or (o2 == 0 and _on_segment(a, b, d))
        or (o3 == 0 and _on_segment(c, d, a))
        or (o4 == 0 and _on_segment(c, d, b))
    )


def signed_area(points: Sequence[Sequence[float]]) -> float:
    """The shoelace area: positive when the vertices run counter-clockwise."""
    n = len(points)
    return 0.5 * sum(
        _cross(points[i][0], points[i][1], points[(i + 1) % n][0], points[(i + 1) % n][1])
        for i in range(n)
    )


def _segment_distance(px: float, py: float, a: Sequence[float], b: Sequence[float]) -> float:
    ex, ey = b[0] - a[0], b[1] - a[1]
    length2 = ex * ex + ey * ey
    t = 0.0 if length2 == 0 else max(0.0, min(1.0, ((px - a[0]) * ex + (py - a[1]) * ey) / length2))
    return math.hypot(px - a[0] - t * ex, py - a[1] - t * ey)


def _inside(px: float, py: float, points: Sequence[Sequence[float]]) -> bool:
    """Crossing-number test (the point on no edge)."""
    inside = False
    n = len(points)
    for i in range(n):
        (x1, y1), (x2, y2) = points[i], points[(i + 1) % n]
        if (y1 > py) != (y2 > py) and px < x1 + (py - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return inside


def polygon_problem(value: Any) -> str | None:
    """Why ``value`` cannot be a footprint polygon (None: it can). The same rules as the robot
    table's CHECKs on ``footprint_polygon`` (schema.sql, migration 17)."""
    problem = _shape_problem(value)
    if problem is not None:
        return problem
    return _geometry_problem([(float(x), float(y)) for x, y in value])


def _shape_problem(value: Any) -> str | None:
    # what the robot table's robot_footprint_polygon_bounded refuses
    if not isinstance(value, list | tuple):
        return f"must be a list of [x, y] vertices, got {value!r}"
    if not MIN_VERTICES <= len(value) <= MAX_VERTICES:
        return f"must have {MIN_VERTICES} to {MAX_VERTICES} vertices, got {len(value)}"
    for i, vertex in enumerate(value):
        if not isinstance(vertex, list | tuple) or len(vertex) != 2:
            return f"vertex {i} must be [x, y], got {vertex!r}"
        for v in vertex:
            if isinstance(v, bool) or not isinstance(v, int | float):
                return f"vertex {i} must be two numbers, got {vertex!r}"
            if not math.isfinite(v):
                return f"vertex {i} must be finite, got {vertex!r}"
            if abs(v) > MAX_COORD_M:
                return (
                    f"vertex {i} must lie within {MAX_COORD_M:g} m of the centre on each axis "
                    f"(a ground robot 10 m across), got {vertex!r}"
                )
    return None


def _geometry_problem(pts: list[tuple[float, float]]) -> str | None:
    # what robot_footprint_polygon_simple and _surrounds_centre refuse
    n = len(pts)
    for i in range(n):
        a, b = pts[i], pts[(i + 1) % n]
        if a == b:
            return f"vertices {i} and {(i + 1) % n} are the same point"
        c = pts[(i + 2) % n]
        # a neighbour folding back along its edge: they overlap, not just share the vertex
        if (
            _orient(a, b, c) == 0
            and (b[0] - a[0]) * (c[0] - b[0]) + (b[1] - a[1]) * (c[1] - b[1]) < 0
        ):
            return f"edges {i} and {(i + 1) % n} fold back on each other (self-intersecting)"
    for i in range(n):
        for j in range(i + 2, n):
            if i == 0 and j == n - 1:
                continue  # neighbours through vertex 0
            if segments_meet(pts[i], pts[(i + 1) % n], pts[j], pts[(j + 1) % n]):
                return f"edges {i} and {j} cross or touch (self-intersecting)"
    if signed_area(pts) <= 0:
        return "must run counter-clockwise (x forward, y left); reverse the vertices"
    if not _inside(0.0, 0.0, pts):
        return "must contain the robot's centre (0, 0)"
    room = min(_segment_distance(0.0, 0.0, pts[i], pts[(i + 1) % n]) for i in range(n))
    if room < MIN_CENTRE_ROOM_M:
        return f"must contain the robot's centre (0, 0) with {MIN_CENTRE_ROOM_M} m to spare"
    return None


@dataclass(frozen=True)
class Footprint:
    """A disc (``polygon`` None) of ``radius_m``, or a polygon (robot frame, CCW)."""

    radius_m: float
    polygon: Polygon | None = None

    @staticmethod
    def of(radius_m: float, polygon: Sequence[Sequence[float]] | None = None) -> Footprint:
        """The footprint of a robot row (``footprint_radius_m``, ``footprint_polygon``);
        ValueError for a polygon :func:`polygon_problem` refuses."""
        if polygon is None:
            return _of(float(radius_m), None)
        return _of(float(radius_m), tuple((float(x), float(y)) for x, y in polygon))

    @property
    def is_disc(self) -> bool:
        return self.polygon is None

    @functools.cached_property
    def vertices(self) -> FloatArray:
        """The polygon's vertices (n x 2, robot frame); a disc's as a 32-gon round it."""
        if self.polygon is not None:
            return np.array(self.polygon, dtype=np.float64)
        # circumscribing the disc, so a check with the polygon never misses what the disc hits
        k = np.arange(32) * (2.0 * np.pi / 32)
        r = self.radius_m / math.cos(math.pi / 32)
        return np.stack([r * np.cos(k), r * np.sin(k)], axis=1)

    @functools.cached_property
    def circumscribed_m(self) -> float:
        """The farthest the footprint reaches from the centre, m."""
        if self.polygon is None:
            return self.radius_m
        return float(np.max(np.hypot(self.vertices[:, 0], self.vertices[:, 1])))

    @functools.cached_property
    def inscribed_m(self) -> float:
        """The nearest the outline comes to the centre, m."""
        if self.polygon is None:
            return self.radius_m
        return float(-self.clearance(np.zeros((1, 2)))[0])

    def at(self, x: float, y: float, yaw: float) -> FloatArray:
        """The polygon (n x 2) at pose (x, y, yaw), world frame."""
        c, s = math.cos(yaw), math.sin(yaw)
        v = self.vertices
        out: FloatArray = np.empty_like(v)
        out[:, 0] = x + c * v[:, 0] - s * v[:, 1]
        out[:, 1] = y + s * v[:, 0] + c * v[:, 1]
        return out

    def clearance(self, points: FloatArray) -> FloatArray:
        """Signed distance (m) from each point (k x 2, robot frame) to the outline: positive
        outside, negative inside."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if self.polygon is None:
            out: FloatArray = np.hypot(pts[:, 0], pts[:, 1]) - self.radius_m
            return out
        a = self.vertices
        e = np.roll(a, -1, axis=0) - a
        rel = pts[:, None, :] - a[None, :, :]  # k x n x 2
        t = np.clip(np.sum(rel * e, axis=2) / np.sum(e * e, axis=1), 0.0, 1.0)
        gap = rel - t[..., None] * e
        dist = np.min(np.hypot(gap[..., 0], gap[..., 1]), axis=1)
        # crossing number, vectorised over points and edges
        y1, y2 = a[:, 1][None, :], np.roll(a[:, 1], -1)[None, :]
        x1, x2 = a[:, 0][None, :], np.roll(a[:, 0], -1)[None, :]
        py, px = pts[:, 1:2], pts[:, 0:1]
        straddle = (y1 > py) != (y2 > py)
        with np.errstate(divide="ignore", invalid="ignore"):
            xcross = x1 + (py - y1) * (x2 - x1) / (y2 - y1)
        inside = np.sum(straddle & (px < xcross), axis=1) % 2 == 1
        signed: FloatArray = np.where(inside, -dist, dist)
        return signed

    def contains(self, points: FloatArray) -> npt.NDArray[np.bool_]:
        """Whether each point (robot frame) is inside the footprint or on its outline."""
        return self.clearance(points) <= 0.0

    def travel_m(self, points: FloatArray, forward: bool = True) -> float:
        """How far (m) the robot can go straight ahead (``forward``) or back before its outline
        meets one of ``points`` (robot frame); inf when none is in its way. A point already
        inside gives 0."""
        each = self.travel_each(points, forward)
        return float(np.min(each)) if len(each) else math.inf

    def travel_each(self, points: FloatArray, forward: bool = True) -> FloatArray:
        """Per point (robot frame), how far the robot goes straight ahead (``forward``) or
        back before its outline meets it: inf for a point beside or behind its way, 0 for
        one already inside. Measured from the outline's front (or back) edge at the
        point's y, so a box's corners count and its sides do not bulge as a disc's would."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if not forward:
            pts = -pts  # backing up is driving ahead in the robot turned round
            shape = Footprint(self.radius_m, None if self.polygon is None else _turned(self))
        else:
            shape = self
        out: FloatArray = np.full(len(pts), np.inf)
        if not len(pts):
            return out
        if shape.polygon is None:
            r = shape.radius_m
            ahead = (pts[:, 0] > 0) & (np.abs(pts[:, 1]) < r)
            out[ahead] = pts[ahead, 0] - np.sqrt(r * r - pts[ahead, 1] ** 2)
        else:
            # the front of the outline at each point's y: the largest x of the polygon there
            v = shape.vertices
            ahead = (pts[:, 1] > np.min(v[:, 1])) & (pts[:, 1] < np.max(v[:, 1]))
            gaps = pts[ahead, 0] - _front_x(v, pts[ahead, 1])
            out[ahead] = np.where(gaps >= 0.0, gaps, np.inf)
        out[shape.contains(pts)] = 0.0
        return out


class Footprinted:
    """A robot described by the contract's two footprint columns: ``footprint_radius_m``,
    and ``footprint_polygon`` (robot frame, counter-clockwise; None: the disc of the
    radius). A dataclass that mixes it in declares the two fields; :attr:`footprint` reads
    them as one shape."""

    footprint_radius_m: float
    footprint_polygon: Polygon | None

    @property
    def footprint(self) -> Footprint:
        """The robot's footprint: its polygon, or the disc of ``footprint_radius_m``."""
        return Footprint.of(self.footprint_radius_m, self.footprint_polygon)


@functools.lru_cache(maxsize=64)
def _of(radius_m: float, polygon: Polygon | None) -> Footprint:
    # cached: every reader of a robot row asks for the same few footprints, and the cached
    # figures (radii, vertices) then come with them
    if polygon is not None:
        problem = polygon_problem(polygon)
        if problem is not None:
            raise ValueError(f"footprint_polygon: {problem}")
    return Footprint(radius_m, polygon)


def _turned(fp: Footprint) -> Polygon:
    # the polygon turned half a turn (still counter-clockwise)
    assert fp.polygon is not None
    return tuple((-x, -y) for x, y in fp.polygon)


def _front_x(v: FloatArray, ys: FloatArray) -> FloatArray:
    """The largest x of the polygon's edges at each y (the outline's front there)."""
    a, b = v, np.roll(v, -1, axis=0)
    y1, y2 = a[:, 1][None, :], b[:, 1][None, :]
    lo, hi = np.minimum(y1, y2), np.maximum(y1, y2)
    y = ys[:, None]
    on = (y >= lo) & (y <= hi) & (hi > lo)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = a[:, 0][None, :] + (y - y1) * (b[:, 0] - a[:, 0])[None, :] / (y2 - y1)
    front: FloatArray = np.max(np.where(on, x, -np.inf), axis=1)
    return front

"""How far each rolled-out pose's footprint is from the nearest lidar hit: the distance
arithmetic of dwa's roll-outs, exact where it can change a decision and cheap elsewhere.

A decision only ever asks "nearer than ``needed`` or not, and how near": whether a pose
comes within the margin, and the smallest gap along an arc up to the clearance cap. So the
nearest hit of a pose is searched only among hits within ``needed`` of its footprint, found
with a sorted-strips index instead of every pose against every hit (a 720-beam scan of
clutter is some 600 hits; a pose has a few dozen within reach): hits sorted by
``(x strip, y)``, per pose and strip one ``searchsorted`` for the y range, the pairs
gathered and measured in float64, the smallest per pose. The hits are also counted per
square cell a strip wide (a summed-area table), so a pose with no hit in the cells around it
is not searched at all (most poses of a long horizon). A pose with no hit that near gets a
value of at least ``needed`` (``inf`` with none in its box), which every caller caps or
compares below ``needed``.

The footprint is the disc of ``radius_m`` (gap: centre distance minus the radius) or a
polygon in the robot's frame (counter-clockwise, metres; gap: the signed distance from the
outline placed at the pose, negative inside), so a box robot's corners count at every
heading. At most bounds.PAIRS_PER_PRODUCT pose x hit pairs are held at once.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

import pnav_local.scratch as scratch
from pnav_local.bounds import PAIRS_PER_PRODUCT, BoolArray, FloatArray

IntArray = npt.NDArray[np.int64]
_STRIPS_PER_REACH = 1  # strip width: the search reach (3 strips a query)
MAX_CELLS = 1 << 16  # the most cells Index counts hits in (a table of 512 KB)
SIFT_FROM = 256  # poses in a query from which the table sifts out those with no hit near


@dataclass(frozen=True)
class Footprint:
    """The robot's outline for the roll-out: a disc, or a polygon (n x 2, CCW) if given."""

    radius_m: float
    polygon: FloatArray | None = None

    @classmethod
    def of(cls, radius_m: float, polygon: Sequence[Sequence[float]] | None) -> Footprint:
        if polygon is None or len(polygon) == 0:
            return cls(radius_m)
        return cls(radius_m, np.asarray(polygon, dtype=np.float64).reshape(-1, 2))

    @property
    def reach_m(self) -> float:
        """The farthest the outline gets from the centre (the circumscribed radius)."""
        if self.polygon is None:
            return self.radius_m
        return float(np.hypot(self.polygon[:, 0], self.polygon[:, 1]).max())


class Index:
    """A scan's hits sorted by (x strip, y), built once per decision: strips half of
    ``reach_m`` wide (the farthest from a pose any query looks)."""

    def __init__(self, obstacles: FloatArray, reach_m: float) -> None:
        self.points = obstacles
        self.width = reach_m / _STRIPS_PER_REACH if math.isfinite(reach_m) else math.inf
        pts = obstacles.reshape(-1, 2).astype(np.float64)
        self.empty = len(pts) == 0
        if self.empty or not math.isfinite(self.width) or self.width <= 0.0:
            self.width = math.inf  # one strip: every hit is a candidate
            strips = np.zeros(len(pts))
        else:
            strips = np.floor(pts[:, 0] / self.width)
        # strips are this far apart on the key, so a y range never crosses into the next
        self.span = 4.0 * (float(np.abs(pts[:, 1]).max(initial=0.0)) + 1.0)
        key = strips * self.span + pts[:, 1]
        order = np.argsort(key, kind="stable")
        self.key = key[order]
        self.x, self.y = pts[order, 0], pts[order, 1]
        self.table: IntArray | None = None
        if not self.empty and math.isfinite(self.width):
            self._count_cells(pts)

    def _count_cells(self, pts: FloatArray) -> None:
        """How many hits lie in each square cell ``width`` wide, as a summed-area table:
        most poses have no hit near, and a few lookups tell so without the strips' search."""
        cx = np.floor(pts[:, 0] / self.width).astype(np.int64)
        cy = np.floor(pts[:, 1] / self.width).astype(np.int64)
        self.x0, self.y0 = int(cx.min()), int(cy.min())
        nx, ny = int(cx.max()) - self.x0 + 1, int(cy.max()) - self.y0 + 1
        if nx * ny > MAX_CELLS:
            return  # a reach too short for the scan's extent: the strips alone
        cells = (cx - self.x0 + 1) * (ny + 1) + (cy - self.y0 + 1)
        table = np.bincount(cells, minlength=(nx + 1) * (ny + 1)).reshape(nx + 1, ny + 1)
        self.table = table.cumsum(axis=0).cumsum(axis=1)

    def near(self, px: FloatArray, py: FloatArray, reach: float) -> BoolArray | None:
        """Per query point, whether any hit lies in the cells within ``reach`` of its cell
        (every hit within ``reach`` of it does); None: no table, every point may have one."""
        table = self.table
        if table is None:
            return None
        k = math.ceil(reach / self.width)
        nx, ny = table.shape[0] - 1, table.shape[1] - 1
        qx = np.floor(px / self.width) - self.x0
        qy = np.floor(py / self.width) - self.y0
        lo_x = np.clip(qx - k, 0, nx).astype(np.int64)
        hi_x = np.clip(qx + k + 1, 0, nx).astype(np.int64)
        lo_y = np.clip(qy - k, 0, ny).astype(np.int64)
        hi_y = np.clip(qy + k + 1, 0, ny).astype(np.int64)
        inside = table[hi_x, hi_y] - table[lo_x, hi_y] - table[hi_x, lo_y] + table[lo_x, lo_y]
        out: BoolArray = inside > 0
        return out

    def pairs(self, px: FloatArray, py: FloatArray, reach: float) -> tuple[IntArray, IntArray]:
        """Per query point (flat) and strip, how many hits its box (``reach`` either side)
        holds and where they start: the hits within ``reach`` of it are among them."""
        n = len(px)
        if self.empty:
            return np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
        if not math.isfinite(self.width):
            return np.full(n, len(self.key), dtype=np.int64), np.zeros(n, dtype=np.int64)
        first = np.floor((px - reach) / self.width)
        count = math.ceil(2.0 * reach / self.width) + 1
        strips = first[:, None] + np.arange(count)[None, :]
        # a pose farther out than any hit's y is clamped to the span: its box is then empty
        half = self.span / 2.0 - 1.0
        low = np.clip(py - reach, -half, half)[:, None]
        high = np.clip(py + reach, -half, half)[:, None]
        lo = np.searchsorted(self.key, (strips * self.span + low).ravel(), "left")
        hi = np.searchsorted(self.key, (strips * self.span + high).ravel(), "right")
        return (hi - lo).astype(np.int64), lo.astype(np.int64)


def _gather(counts: IntArray, starts: IntArray) -> IntArray:
    """The hit indices of every box, box after box."""
    total = int(counts.sum())
    ends = np.cumsum(counts)
    out: IntArray = np.repeat(starts - (ends - counts), counts)
    out += scratch.arange(total)
    return out


def _box(polygon: FloatArray) -> tuple[float, float, float, float] | None:
    """(centre x, centre y, half length, half width) when the polygon is a rectangle with
    sides along the robot's axes (most bases' footprints, the Jackal's); None otherwise.
    Judged once per outline: a few dozen microseconds of numpy calls, asked several times
    a decision."""
    if len(polygon) != 4:
        return None
    return _box_of(np.ascontiguousarray(polygon, dtype=np.float64).tobytes())


@functools.lru_cache(maxsize=16)
def _box_of(raw: bytes) -> tuple[float, float, float, float] | None:
    """:func:`_box` of the 4-vertex polygon whose float64 coordinates ``raw`` holds."""
    polygon = np.frombuffer(raw, dtype=np.float64).reshape(4, 2)
    xs, ys = polygon[:, 0], polygon[:, 1]
    lo_x, hi_x, lo_y, hi_y = xs.min(), xs.max(), ys.min(), ys.max()
    # every vertex a corner of the bounding box, each corner once
    corners = {(bool(x == hi_x), bool(y == hi_y)) for x, y in polygon}
    if not (np.isin(xs, (lo_x, hi_x)).all() and np.isin(ys, (lo_y, hi_y)).all()):
        return None
    if len(corners) != 4 or hi_x <= lo_x or hi_y <= lo_y:
        return None
    return (
        float(lo_x + hi_x) / 2.0,
        float(lo_y + hi_y) / 2.0,
        float(hi_x - lo_x) / 2.0,
        float(hi_y - lo_y) / 2.0,
    )


def _polygon_gap(qx: FloatArray, qy: FloatArray, polygon: FloatArray) -> FloatArray:
    """Signed distance of points (robot frame) from the polygon's outline: negative inside."""
    box = _box(polygon)
    if box is not None:
        # a rectangle along the axes in closed form: a few operations per point instead of
        # one per point and edge (most of a box's roll-out was the general form below)
        cx, cy, hx, hy = box
        dx, dy = np.abs(qx - cx) - hx, np.abs(qy - cy) - hy
        outside = np.sqrt(np.maximum(dx, 0.0) ** 2 + np.maximum(dy, 0.0) ** 2)
        boxed: FloatArray = np.where((dx < 0.0) & (dy < 0.0), np.maximum(dx, dy), outside)
        return boxed
    a = polygon
    b = np.roll(polygon, -1, axis=0)
    ab = b - a
    length2 = np.maximum((ab * ab).sum(axis=1), 1e-18)
    rx = qx[:, None] - a[None, :, 0]
    ry = qy[:, None] - a[None, :, 1]
    t = np.clip((rx * ab[None, :, 0] + ry * ab[None, :, 1]) / length2[None, :], 0.0, 1.0)
    ex, ey = rx - t * ab[None, :, 0], ry - t * ab[None, :, 1]
    # np.hypot is several times slower than this, and these are far from overflowing
    dist = np.sqrt((ex * ex + ey * ey).min(axis=1))
    # even-odd crossings of a ray toward +x
    ay, by = a[None, :, 1], b[None, :, 1]
    straddle = (ay > qy[:, None]) != (by > qy[:, None])
    denom = np.where(by == ay, 1.0, by - ay)
    cross_x = a[None, :, 0] + (qy[:, None] - ay) * (b[None, :, 0] - a[None, :, 0]) / denom
    inside = (straddle & (qx[:, None] < cross_x)).sum(axis=1) % 2 == 1
    out: FloatArray = np.where(inside, -dist, dist)
    return out


def _box_order(
    qx: FloatArray, qy: FloatArray, box: tuple[float, float, float, float], inside: FloatArray
) -> FloatArray:
    """Per point (robot frame), what orders its gap from the axis-aligned box ``box``
    (:func:`_box`) as the gap does: the signed gap inside (negative), its square outside;
    :func:`_polygon_gap`'s closed form without the root per point. In ``qx`` (``qy`` and
    ``inside``, as long, are overwritten too)."""
    cx, cy, hx, hy = box
    if cx != 0.0:
        qx -= cx
    if cy != 0.0:
        qy -= cy
    dx = np.abs(qx, out=qx)
    dx -= hx
    dy = np.abs(qy, out=qy)
    dy -= hy
    np.maximum(dx, dy, out=inside)  # < 0: both are, and the gap is the nearer side's
    np.maximum(dx, 0.0, out=dx)
    np.maximum(dy, 0.0, out=dy)
    dx *= dx
    dy *= dy
    dx += dy
    np.copyto(dx, inside, where=inside < 0.0)
    return dx


def gaps(
    xs: FloatArray,
    ys: FloatArray,
    yaws: FloatArray | None,
    hits: FloatArray | Index,
    footprint: Footprint,
    needed_m: float,
) -> FloatArray:
    """Per pose (any shape), the gap between its footprint and the nearest hit: exact below
    ``needed_m``, at least ``needed_m`` otherwise (``inf`` with no hit near). ``yaws``
    matter to a polygon only (None: every pose facing +x). ``hits``: the points, or their
    Index (built once for the decision's several calls)."""
    shape = xs.shape
    px, py = xs.ravel().astype(np.float64), ys.ravel().astype(np.float64)
    reach = footprint.reach_m + max(needed_m, 0.0)
    index = hits if isinstance(hits, Index) else Index(hits, reach)
    polygon = footprint.polygon
    if polygon is None:
        out = np.sqrt(squared(px, py, index, reach)) - footprint.radius_m
        return out.reshape(shape)
    headings = np.zeros(len(px)) if yaws is None else yaws.ravel().astype(np.float64)
    return _nearest(px, py, headings, index, reach, polygon).reshape(shape)


def squared(px: FloatArray, py: FloatArray, index: Index, reach: float) -> FloatArray:
    """Per point (flat, float64), the squared distance to its nearest hit: exact within
    ``reach``, at least ``reach**2`` otherwise (``inf`` with none in its box). What
    ``gaps`` of a disc takes the root of; dwa asks it once for several kinds of point."""
    return _nearest(px, py, None, index, reach, None)


def _nearest(
    px: FloatArray,
    py: FloatArray,
    headings: FloatArray | None,
    index: Index,
    reach: float,
    polygon: FloatArray | None,
    sifted: bool = False,
) -> FloatArray:
    """Per point, the smallest over the hits of its box: the squared distance (no polygon)
    or the polygon's signed gap (the hit in the frame of the robot at the pose). ``sifted``:
    every point has a hit in the cells near it (Index.near said so)."""
    out = np.full(len(px), np.inf)
    if index.empty or len(px) == 0:
        return out
    # a few poses are searched for less than the table's lookups cost
    near = None if sifted or len(px) < SIFT_FROM else index.near(px, py, reach)
    if near is not None and not near.all():
        # only the points with a hit near are searched; the others have none within reach
        some = np.flatnonzero(near)
        if len(some):
            out[some] = _nearest(
                px[some], py[some], None if headings is None else headings[some],
                index, reach, polygon, sifted=True,
            )  # fmt: skip
        return out
    counts, starts = index.pairs(px, py, reach)
    boxes = len(counts) // len(px)
    per_pose = counts.reshape(len(px), boxes).sum(axis=1)
    box = None
    if polygon is not None and headings is not None:
        cos, sin = np.cos(headings), np.sin(headings)
        box = _box(polygon)
    # poses in runs of at most PAIRS_PER_PRODUCT pairs (a single pose's box may exceed it);
    # mostly one run, found without a search
    done = np.cumsum(per_pose)
    begin = 0
    while begin < len(px):
        if done[-1] - (done[begin - 1] if begin else 0) <= PAIRS_PER_PRODUCT:
            end = len(px)
        else:
            before = done[begin - 1] if begin else 0
            end = int(np.searchsorted(done, before + PAIRS_PER_PRODUCT, "right"))
            end = min(len(px), max(end, begin + 1))
        c, s = counts[begin * boxes : end * boxes], starts[begin * boxes : end * boxes]
        found = _gather(c, s)
        n = per_pose[begin:end]
        # the pairs' arithmetic in place, in scratch arrays (scratch.py: fresh ones cost more
        # in page faults than the arithmetic), each pose's values taken to its pairs by owner
        pairs = len(found)
        owner = np.repeat(scratch.arange(end - begin), n)
        tmp = scratch.array("tmp", pairs)
        dx = np.take(index.x, found, out=scratch.array("dx", pairs), mode="clip")
        dx -= np.take(px[begin:end], owner, out=tmp, mode="clip")
        dy = np.take(index.y, found, out=scratch.array("dy", pairs), mode="clip")
        dy -= np.take(py[begin:end], owner, out=tmp, mode="clip")
        if polygon is None or headings is None:
            dx *= dx
            dy *= dy
            dx += dy
            d = dx  # squared: one root per pose (the caller's), not per pair
        else:
            co = np.take(cos[begin:end], owner, out=scratch.array("co", pairs), mode="clip")
            so = np.take(sin[begin:end], owner, out=scratch.array("so", pairs), mode="clip")
            # (co dx + so dy, -so dx + co dy): the same sums, bit for bit
            qx = np.multiply(co, dx, out=scratch.array("qx", pairs))
            qx += np.multiply(so, dy, out=tmp)
            qy = np.multiply(co, dy, out=co)
            qy -= np.multiply(so, dx, out=tmp)
            if box is not None:
                d = _box_order(qx, qy, box, scratch.array("inside", pairs))
            else:
                d = _polygon_gap(qx, qy, polygon)
        if len(d):
            at = done[begin:end] - done[begin] + n[0] - n  # each pose's first pair
            some = n > 0
            if some.all():
                out[begin:end] = np.minimum.reduceat(d, at)
            else:
                out[begin:end][some] = np.minimum.reduceat(d, at[some])
        begin = end
    if box is not None:
        # _box_order's values: the signed gap inside, the squared gap outside (a root is
        # monotone, so the root of the smallest is the smallest root, bit for bit)
        np.sqrt(out, out=out, where=out > 0.0)
    return out

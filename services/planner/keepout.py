"""Keepout zones on the planning grid: a zone's cells are obstacles, like the map's walls.

A keepout zone (the zone table, CONTRACT.md) is a polygon in the map frame. Its cells are
added to the map's occupancy before the grid is inflated (grid.py), so the robot's whole
footprint stays out of the zone, as it stays off a wall, and every route, distance and
reachability proof the planner works out on that grid goes round it (as Nav2's keepout
filter marks the costmap). A cell is the zone's when its centre is inside the polygon, and
so is every cell an edge passes through: a zone narrower than a cell still closes the way.
Everything here is pure (numpy), unit-tested on hand-made grids.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from common.contract.zones import Zone

BoolGrid = np.ndarray[Any, np.dtype[np.bool_]]


def _digest(zones: Iterable[Zone]) -> str:
    text = repr(sorted((z.name, z.xs, z.ys) for z in zones if z.keepout))
    return hashlib.sha1(text.encode()).hexdigest()[:12]


class Keepouts(tuple[Zone, ...]):
    """The keepout zones that apply to one robot, by name, with their digest worked out once
    (``World.keepouts`` keeps one per robot until the zones are read changed)."""

    key: str

    def __new__(cls, zones: Iterable[Zone]) -> Keepouts:
        held = super().__new__(cls, sorted((z for z in zones if z.keepout), key=lambda z: z.name))
        held.key = _digest(held)
        return held


def zones_key(zones: Iterable[Zone]) -> str:
    """A short digest of the keepout zones' names and polygons: equal for the same set, so
    a planning grid (and a route made on it) is kept exactly while the zones stay."""
    if isinstance(zones, Keepouts):
        return zones.key
    return _digest(zones)


def _to_cells(
    xs: Sequence[float],
    ys: Sequence[float],
    resolution: float,
    origin: tuple[float, float, float],
) -> tuple[np.ndarray[Any, np.dtype[np.float64]], np.ndarray[Any, np.dtype[np.float64]]]:
    """World vertices -> fractional (col, row), as PlanGrid.to_cell."""
    ox, oy, yaw = origin
    dx, dy = np.asarray(xs, dtype=np.float64) - ox, np.asarray(ys, dtype=np.float64) - oy
    if yaw:
        c, s = math.cos(yaw), math.sin(yaw)
        dx, dy = c * dx + s * dy, -s * dx + c * dy
    return dx / resolution, dy / resolution


def _centres_inside(
    cols: np.ndarray[Any, np.dtype[np.float64]],
    rows: np.ndarray[Any, np.dtype[np.float64]],
    c0: int,
    c1: int,
    r0: int,
    r1: int,
) -> BoolGrid:
    """Which cells of the window have their centre inside the polygon (even-odd rule), by
    scanlines: per row of centres, where each edge crosses it; a cell is inside when an odd
    number of crossings lie to the right of its centre. O(rows x edges + cells), not
    O(cells x edges): a zone as large as the map costs a few milliseconds."""
    cy = np.arange(r0, r1, dtype=np.float64)[:, None] + 0.5
    x1, y1 = np.roll(cols, 1)[None, :], np.roll(rows, 1)[None, :]
    x2, y2 = cols[None, :], rows[None, :]
    spans = (y1 > cy) != (y2 > cy)  # (rows, edges); a horizontal edge spans no row
    with np.errstate(divide="ignore", invalid="ignore"):
        at = x1 + (cy - y1) * (x2 - x1) / (y2 - y1)
    width = c1 - c0
    # the crossing at ``at`` lies to the right of the centres of the first k cells
    k = np.clip(np.ceil(np.where(spans, at, -np.inf) - c0 - 0.5), 0, width).astype(np.int64)
    right = np.zeros((r1 - r0, width + 1), dtype=np.int64)
    row_index = np.broadcast_to(np.arange(r1 - r0)[:, None], k.shape)
    np.add.at(right, (row_index[spans], k[spans]), 1)
    # crossings right of cell j: those with k > j
    counts = np.cumsum(right[:, ::-1], axis=1)[:, ::-1][:, 1:]
    return np.asarray(counts % 2 == 1, dtype=np.bool_)


def _clip(ax: float, ay: float, bx: float, by: float, w: int, h: int) -> tuple[float, float] | None:
    """The part (t0, t1) of the segment a + t (b - a), t in [0, 1], over the grid (one cell
    of slack round it; Liang-Barsky); None when it misses the grid."""
    t0, t1 = 0.0, 1.0
    for delta, start, low, high in ((bx - ax, ax, -1.0, w + 1.0), (by - ay, ay, -1.0, h + 1.0)):
        if delta == 0.0:
            if not low <= start <= high:
                return None
            continue
        ta, tb = (low - start) / delta, (high - start) / delta
        t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
        if t0 > t1:
            return None
    return t0, t1


def zone_cells(
    zone: Zone, shape: tuple[int, int], resolution: float, origin: tuple[float, float, float]
) -> BoolGrid:
    """The cells of a (height, width) grid the zone covers (see the module docstring)."""
    h, w = shape
    out = np.zeros(shape, dtype=np.bool_)
    cols, rows = _to_cells(zone.xs, zone.ys, resolution, origin)
    c0, c1 = max(0, math.floor(cols.min())), min(w, math.floor(cols.max()) + 1)
    r0, r1 = max(0, math.floor(rows.min())), min(h, math.floor(rows.max()) + 1)
    if c0 >= c1 or r0 >= r1:
        return out  # off the map
    out[r0:r1, c0:c1] = _centres_inside(cols, rows, c0, c1, r0, r1)
    n = len(cols)
    # the edges' own cells, sampled at a quarter of a cell, on the part over the map only
    for i in range(n):
        ax, ay, bx, by = cols[i - 1], rows[i - 1], cols[i], rows[i]
        span = _clip(ax, ay, bx, by, w, h)
        if span is None:
            continue
        t0, t1 = span
        steps = max(1, math.ceil(4 * math.hypot(bx - ax, by - ay) * (t1 - t0)))
        t = np.linspace(t0, t1, steps + 1)
        ec = np.floor(ax + (bx - ax) * t).astype(np.int64)
        er = np.floor(ay + (by - ay) * t).astype(np.int64)
        on = (ec >= 0) & (er >= 0) & (ec < w) & (er < h)
        out[er[on], ec[on]] = True
    return out


def with_keepouts(
    occupied: BoolGrid,
    zones: Iterable[Zone],
    resolution: float,
    origin: tuple[float, float, float],
) -> BoolGrid:
    """``occupied`` with every keepout zone's cells occupied too (a copy; ``occupied`` as
    given when there is none)."""
    out = occupied
    for zone in zones:
        if not zone.keepout:
            continue
        if out is occupied:
            out = occupied.copy()
        out |= zone_cells(zone, occupied.shape, resolution, origin)
    return out


def containing(zones: Iterable[Zone], x: float, y: float) -> Zone | None:
    """The first keepout zone (by name) with (x, y) inside it."""
    return next((z for z in sorted(zones, key=lambda z: z.name) if z.contains(x, y)), None)


def names(zones: Iterable[Zone]) -> str:
    """``'a', 'b'``: the keepout zones named for people."""
    return ", ".join(f"'{z.name}'" for z in sorted(zones, key=lambda z: z.name) if z.keepout)

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


def zones_key(zones: Iterable[Zone]) -> str:
    """A short digest of the keepout zones' names and polygons: equal for the same set, so
    a planning grid (and a route made on it) is kept exactly while the zones stay."""
    text = repr(sorted((z.name, z.xs, z.ys) for z in zones if z.keepout))
    return hashlib.sha1(text.encode()).hexdigest()[:12]


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
    # centres inside: the even-odd rule over the window, one edge at a time
    cx = np.arange(c0, c1, dtype=np.float64)[None, :] + 0.5
    cy = np.arange(r0, r1, dtype=np.float64)[:, None] + 0.5
    inside = np.zeros((r1 - r0, c1 - c0), dtype=np.bool_)
    n = len(cols)
    for i in range(n):
        xi, yi, xj, yj = cols[i], rows[i], cols[i - 1], rows[i - 1]
        if yi == yj:
            continue  # a horizontal edge crosses no horizontal ray
        spans = (yi > cy) != (yj > cy)
        at = (xj - xi) * (cy - yi) / (yj - yi) + xi
        inside ^= spans & (cx < at)
    out[r0:r1, c0:c1] = inside
    # the edges' own cells, sampled at a quarter of a cell
    for i in range(n):
        ax, ay, bx, by = cols[i - 1], rows[i - 1], cols[i], rows[i]
        steps = max(1, math.ceil(4 * math.hypot(bx - ax, by - ay)))
        t = np.linspace(0.0, 1.0, steps + 1)
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

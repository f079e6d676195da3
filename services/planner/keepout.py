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


def _edge_cells(
    cols: np.ndarray[Any, np.dtype[np.float64]],
    rows: np.ndarray[Any, np.dtype[np.float64]],
    w: int,
    h: int,
) -> tuple[np.ndarray[Any, np.dtype[np.int64]], np.ndarray[Any, np.dtype[np.int64]]]:
    """The (cols, rows) of the grid cells the polygon's edges pass through: every edge
    sampled at a quarter of a cell, on the part of it over the grid only (clipped to the
    grid and a cell round it, Liang-Barsky), all edges at once."""
    ax, ay = np.roll(cols, 1), np.roll(rows, 1)
    dx, dy = cols - ax, rows - ay
    t0, t1 = np.zeros(len(cols)), np.ones(len(cols))
    keep = np.ones(len(cols), dtype=np.bool_)
    with np.errstate(divide="ignore", invalid="ignore"):
        for delta, start, high in ((dx, ax, w + 1.0), (dy, ay, h + 1.0)):
            flat = delta == 0.0
            keep &= ~flat | ((start >= -1.0) & (start <= high))
            ta, tb = (-1.0 - start) / delta, (high - start) / delta
            t0 = np.where(flat, t0, np.maximum(t0, np.minimum(ta, tb)))
            t1 = np.where(flat, t1, np.minimum(t1, np.maximum(ta, tb)))
    keep &= t0 <= t1
    steps = np.where(keep, np.maximum(1, np.ceil(4 * np.hypot(dx, dy) * (t1 - t0))), 0)
    counts = np.where(keep, steps + 1, 0).astype(np.int64)
    edge = np.repeat(np.arange(len(cols)), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    t = t0[edge] + (t1 - t0)[edge] * (np.arange(len(edge)) - first) / steps[edge]
    ec = np.floor(ax[edge] + dx[edge] * t).astype(np.int64)
    er = np.floor(ay[edge] + dy[edge] * t).astype(np.int64)
    on = (ec >= 0) & (er >= 0) & (ec < w) & (er < h)
    return ec[on], er[on]


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
    ec, er = _edge_cells(cols, rows, w, h)
    out[er, ec] = True
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

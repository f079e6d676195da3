"""The planning grid: the map table's occupancy grid inflated, costed and coarsened for A*.

The grid comes from the ``map`` table (row 0 at the bottom, 0 free, 100 occupied, 255
unknown). Unknown counts as occupied: a robot should not plan through space nobody has seen.

Like Nav2's inflation layer, the planner works on the *clearance* of every cell (the distance
from its centre to the nearest obstacle cell's centre, a distance transform):

- cells closer to an obstacle than the robot's footprint radius plus a margin are blocked,
  so the robot's *centre* can be planned as a point;
- cells within ``cost_radius_m`` of an obstacle cost more to cross, the more the closer, so
  A* keeps away from walls where it can: along the middle of an aisle, wide around a corner.

The search on it (A*, shortcut) is in path.py. Everything here is pure (no database, no
engine), so it is unit-tested on hand-made grids.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, TypeAlias

import numpy as np

XY: TypeAlias = tuple[float, float]
Cell: TypeAlias = tuple[int, int]  # (col, row)
BoolGrid: TypeAlias = np.ndarray[Any, np.dtype[np.bool_]]
FloatGrid: TypeAlias = np.ndarray[Any, np.dtype[np.float64]]

# Cells at or above this value are obstacles: 100 (occupied) and 255 (unknown) in the
# trinary maps we ship, and "more likely occupied than not" in scaled ROS maps.
OCCUPIED_AT = 50
# Above this many cells the planning grid is coarsened (max-pooled), so one A* stays in the
# tens of milliseconds even on a large warehouse map.
MAX_PLAN_CELLS = 160_000
# Clearance costs: a cell whose clearance c is below COST_RADIUS_M costs
# 1 + COST_WEIGHT * ((COST_RADIUS_M - c) / (COST_RADIUS_M - inflation))^2 per unit of length
# (1 in the open; 1 + COST_WEIGHT at the edge of the blocked zone).
COST_RADIUS_M = 0.6
COST_WEIGHT = 3.0


def clearance_cells(occupied: BoolGrid, cap_cells: int) -> FloatGrid:
    """Euclidean distance, in cells, from every cell's centre to the nearest occupied cell's
    centre; exact up to ``cap_cells``, and ``cap_cells`` wherever it is farther.

    A separable distance transform in numpy: the distance to the nearest occupied cell in the
    same column (two sweeps over the rows), then for each cell the minimum over the columns
    within the cap of dx^2 + that column distance^2.
    """
    h, w = occupied.shape
    cap = max(1, int(cap_cells))
    # no column is more than w away: a larger cap (a footprint row of any size) changes no
    # distance, only the work (one pass over the grid per column within it)
    reach = min(cap, w)
    far = float(cap + 1)
    column = np.where(occupied, 0.0, far)
    for r in range(1, h):
        np.minimum(column[r], column[r - 1] + 1.0, out=column[r])
    for r in range(h - 2, -1, -1):
        np.minimum(column[r], column[r + 1] + 1.0, out=column[r])
    squared = column * column
    padded = np.pad(squared, ((0, 0), (reach, reach)), constant_values=far * far)
    best = squared.copy()
    for dx in range(1, reach + 1):
        np.minimum(best, padded[:, reach + dx : reach + dx + w] + dx * dx, out=best)
        np.minimum(best, padded[:, reach - dx : reach - dx + w] + dx * dx, out=best)
    return np.asarray(np.minimum(np.sqrt(best), float(cap)), dtype=np.float64)


def inflate(occupied: BoolGrid, radius_cells: float) -> BoolGrid:
    """Every cell whose centre is within ``radius_cells`` of an occupied cell's centre."""
    if radius_cells < 1.0:
        return occupied.copy()
    distance = clearance_cells(occupied, math.floor(radius_cells) + 1)
    return np.asarray(distance * distance <= radius_cells * radius_cells + 1e-9, dtype=np.bool_)


def coarsen(blocked: BoolGrid, factor: int) -> BoolGrid:
    """Max-pool ``blocked`` by ``factor``: a coarse cell is blocked if any fine cell is."""
    if factor <= 1:
        return blocked
    h, w = blocked.shape
    ph, pw = -h % factor, -w % factor
    padded = np.pad(blocked, ((0, ph), (0, pw)), constant_values=True)
    hh, ww = padded.shape
    pooled = padded.reshape(hh // factor, factor, ww // factor, factor).any(axis=(1, 3))
    return np.asarray(pooled, dtype=np.bool_)


def _coarsen_min(values: FloatGrid, factor: int) -> FloatGrid:
    """Min-pool ``values`` by ``factor`` (a coarse cell is as close to obstacles as its worst
    fine cell); the padding past the edge counts as 0."""
    if factor <= 1:
        return values
    h, w = values.shape
    padded = np.pad(values, ((0, -h % factor), (0, -w % factor)), constant_values=0.0)
    hh, ww = padded.shape
    pooled = padded.reshape(hh // factor, factor, ww // factor, factor).min(axis=(1, 3))
    return np.asarray(pooled, dtype=np.float64)


@dataclass
class PlanGrid:
    """An inflated (maybe coarsened) grid in world coordinates, ready for A*.

    ``clearance`` (metres per cell, capped at ``cost_radius_m``) is optional: without it every
    free cell costs the same and the shortcut only checks line of sight.
    """

    blocked: BoolGrid
    resolution: float
    origin_x: float
    origin_y: float
    origin_yaw: float = 0.0
    clearance: FloatGrid | None = None
    inflation_m: float = 0.0  # the blocked zone's radius around obstacles
    cost_radius_m: float = 0.0
    cost_weight: float = 0.0
    _flat: list[bool] | None = field(default=None, repr=False)
    _costs: list[float] | None = field(default=None, repr=False)

    @property
    def shape(self) -> tuple[int, int]:
        h, w = self.blocked.shape
        return int(h), int(w)

    @property
    def costed(self) -> bool:
        return self.clearance is not None and self.cost_weight > 0.0 and self.cost_radius_m > 0.0

    def with_cells(self, blocked: BoolGrid, clearance: FloatGrid | None) -> PlanGrid:
        """This grid's frame, inflation and costs over other cells (its caches not copied)."""
        return PlanGrid(
            blocked,
            self.resolution,
            self.origin_x,
            self.origin_y,
            self.origin_yaw,
            clearance=clearance,
            inflation_m=self.inflation_m,
            cost_radius_m=self.cost_radius_m,
            cost_weight=self.cost_weight,
        )

    def to_cell(self, x: float, y: float) -> tuple[float, float]:
        """World point -> fractional (col, row); cell (i, j) spans [i, i+1) x [j, j+1)."""
        dx, dy = x - self.origin_x, y - self.origin_y
        if self.origin_yaw:
            c, s = math.cos(self.origin_yaw), math.sin(self.origin_yaw)
            dx, dy = c * dx + s * dy, -s * dx + c * dy
        return dx / self.resolution, dy / self.resolution

    def cell_of(self, x: float, y: float) -> Cell:
        fc, fr = self.to_cell(x, y)
        return math.floor(fc), math.floor(fr)

    def to_world(self, cell: Cell) -> XY:
        """Centre of ``cell`` in the world frame."""
        dx, dy = (cell[0] + 0.5) * self.resolution, (cell[1] + 0.5) * self.resolution
        if self.origin_yaw:
            c, s = math.cos(self.origin_yaw), math.sin(self.origin_yaw)
            dx, dy = c * dx - s * dy, s * dx + c * dy
        return self.origin_x + dx, self.origin_y + dy

    def cells_of(
        self, points: np.ndarray[Any, np.dtype[np.float64]]
    ) -> tuple[
        np.ndarray[Any, np.dtype[np.int64]],
        np.ndarray[Any, np.dtype[np.int64]],
        np.ndarray[Any, np.dtype[np.bool_]],
    ]:
        """The (cols, rows) of the cells under world ``points`` (an (n, 2) array), and which
        of them are inside the grid."""
        dx, dy = points[:, 0] - self.origin_x, points[:, 1] - self.origin_y
        if self.origin_yaw:
            c, s = math.cos(self.origin_yaw), math.sin(self.origin_yaw)
            dx, dy = c * dx + s * dy, -s * dx + c * dy
        cols = np.floor(dx / self.resolution).astype(np.int64)
        rows = np.floor(dy / self.resolution).astype(np.int64)
        h, w = self.shape
        inside = (cols >= 0) & (rows >= 0) & (cols < w) & (rows < h)
        return cols, rows, np.asarray(inside, dtype=np.bool_)

    def inside(self, cell: Cell) -> bool:
        h, w = self.shape
        return 0 <= cell[0] < w and 0 <= cell[1] < h

    def free(self, cell: Cell) -> bool:
        return self.inside(cell) and not bool(self.blocked[cell[1], cell[0]])

    def clearance_at(self, cell: Cell) -> float:
        """The cell's clearance (m), capped at ``cost_radius_m``; inf without a clearance map."""
        if self.clearance is None:
            return math.inf
        return float(self.clearance[cell[1], cell[0]])

    def padded_flat(self) -> list[bool]:
        """The grid with a one-cell blocked border, flattened: A* then needs no bounds test.
        Cached: converting to a Python list is the costly part and the grid never changes."""
        if self._flat is None:
            padded = np.pad(self.blocked, 1, constant_values=True)
            self._flat = padded.ravel().tolist()
        return self._flat

    def padded_costs(self) -> list[float]:
        """Per cell, the cost of a unit of length through it (>= 1), padded and flattened as
        :meth:`padded_flat`; all ones without clearance costs. Cached."""
        if self._costs is None:
            if self.costed:
                assert self.clearance is not None
                span = max(self.cost_radius_m - self.inflation_m, 1e-6)
                closeness = np.clip((self.cost_radius_m - self.clearance) / span, 0.0, 1.0)
                costs = 1.0 + self.cost_weight * closeness * closeness
            else:
                costs = np.ones(self.blocked.shape)
            self._costs = np.pad(costs, 1, constant_values=1.0).ravel().tolist()
        return self._costs


def plan_grid(
    occupied: BoolGrid,
    resolution: float,
    origin: tuple[float, float, float],
    inflation_m: float,
    max_cells: int = MAX_PLAN_CELLS,
    cost_radius_m: float = COST_RADIUS_M,
    cost_weight: float = COST_WEIGHT,
) -> PlanGrid:
    """Block every cell within ``inflation_m`` of an obstacle, cost the cells within
    ``cost_radius_m``, then coarsen if the grid is too large."""
    radius_m = max(inflation_m, cost_radius_m)
    cells = clearance_cells(occupied, math.ceil(radius_m / resolution) + 1)
    clearance = np.minimum(cells * resolution, radius_m)
    reach = inflation_m / resolution
    blocked = np.asarray(cells * cells <= reach * reach + 1e-9, dtype=np.bool_)
    factor = max(1, math.ceil(math.sqrt(blocked.size / max_cells)))
    return PlanGrid(
        coarsen(blocked, factor),
        resolution * factor,
        *origin,
        clearance=_coarsen_min(clearance, factor),
        inflation_m=inflation_m,
        cost_radius_m=cost_radius_m,
        cost_weight=cost_weight,
    )


def with_obstacles(grid: PlanGrid, points: np.ndarray[Any, np.dtype[np.float64]]) -> PlanGrid:
    """A copy of ``grid`` with more obstacles: the cells under the world ``points`` (an (n, 2)
    array, e.g. lidar hits on things the map does not show) are blocked and costed exactly
    like the map's own obstacles. ``grid`` itself is left alone (it is cached per map)."""
    if len(points) == 0:
        return grid
    cols, rows, inside = grid.cells_of(points)
    cols, rows = cols[inside], rows[inside]
    if cols.size == 0:
        return grid
    h, w = grid.shape
    reach = math.ceil(max(grid.inflation_m, grid.cost_radius_m) / grid.resolution) + 1
    c0, c1 = max(0, int(cols.min()) - reach), min(w, int(cols.max()) + reach + 1)
    r0, r1 = max(0, int(rows.min()) - reach), min(h, int(rows.max()) + reach + 1)
    occupied = np.zeros((r1 - r0, c1 - c0), dtype=np.bool_)
    occupied[rows - r0, cols - c0] = True
    distance = clearance_cells(occupied, reach)
    limit = grid.inflation_m / grid.resolution
    blocked = grid.blocked.copy()
    blocked[r0:r1, c0:c1] |= distance * distance <= limit * limit + 1e-9
    clearance = grid.clearance
    if clearance is not None:
        clearance = clearance.copy()
        near = np.minimum(distance * grid.resolution, max(grid.inflation_m, grid.cost_radius_m))
        np.minimum(clearance[r0:r1, c0:c1], near, out=clearance[r0:r1, c0:c1])
    return grid.with_cells(blocked, clearance)

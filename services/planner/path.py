"""Paths on the map table's occupancy grid: clearance, costed 8-connected A*, shortcut.

The grid comes from the ``map`` table (row 0 at the bottom, 0 free, 100 occupied, 255
unknown). Unknown counts as occupied: a robot should not plan through space nobody has seen.

Like Nav2's inflation layer, the planner works on the *clearance* of every cell (the distance
from its centre to the nearest obstacle cell's centre, a distance transform):

- cells closer to an obstacle than the robot's footprint radius plus a margin are blocked,
  so the robot's *centre* can be planned as a point;
- cells within ``cost_radius_m`` of an obstacle cost more to cross, the more the closer, so
  A* keeps away from walls where it can: along the middle of an aisle, wide around a corner;
- the A* staircase is then straightened with line-of-sight checks that also keep the
  clearance: a straight segment replaces a stretch of the path only if it comes no closer to
  an obstacle than that stretch did (or than ``cost_radius_m``), so a shortcut never cuts
  back to the walls.

Everything here is pure (no database, no engine), so it is unit-tested on hand-made grids.
"""

from __future__ import annotations

import heapq
import itertools
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
# How far (m) a start or goal inside an inflated obstacle may be moved to the nearest free cell.
SNAP_RADIUS_M = 0.6
# Clearance costs: a cell whose clearance c is below COST_RADIUS_M costs
# 1 + COST_WEIGHT * ((COST_RADIUS_M - c) / (COST_RADIUS_M - inflation))^2 per unit of length
# (1 in the open; 1 + COST_WEIGHT at the edge of the blocked zone).
COST_RADIUS_M = 0.6
COST_WEIGHT = 3.0
# A shortcut keeps, at each point, the path's clearance within this distance along the path.
SHORTCUT_WINDOW_M = 0.3
_SQRT2 = math.sqrt(2.0)


def clearance_cells(occupied: BoolGrid, cap_cells: int) -> FloatGrid:
    """Euclidean distance, in cells, from every cell's centre to the nearest occupied cell's
    centre; exact up to ``cap_cells``, and ``cap_cells`` wherever it is farther.

    A separable distance transform in numpy: the distance to the nearest occupied cell in the
    same column (two sweeps over the rows), then for each cell the minimum over the columns
    within the cap of dx^2 + that column distance^2.
    """
    h, w = occupied.shape
    cap = max(1, int(cap_cells))
    far = float(cap + 1)
    column = np.where(occupied, 0.0, far)
    for r in range(1, h):
        np.minimum(column[r], column[r - 1] + 1.0, out=column[r])
    for r in range(h - 2, -1, -1):
        np.minimum(column[r], column[r + 1] + 1.0, out=column[r])
    squared = column * column
    padded = np.pad(squared, ((0, 0), (cap, cap)), constant_values=far * far)
    best = squared.copy()
    for dx in range(1, cap + 1):
        np.minimum(best, padded[:, cap + dx : cap + dx + w] + dx * dx, out=best)
        np.minimum(best, padded[:, cap - dx : cap - dx + w] + dx * dx, out=best)
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
    return PlanGrid(
        blocked,
        grid.resolution,
        grid.origin_x,
        grid.origin_y,
        grid.origin_yaw,
        clearance=clearance,
        inflation_m=grid.inflation_m,
        cost_radius_m=grid.cost_radius_m,
        cost_weight=grid.cost_weight,
    )


def astar(grid: PlanGrid, start: Cell, goal: Cell) -> list[Cell] | None:
    """Cheapest 8-connected cell path from ``start`` to ``goal``, or None if there is none.

    A step costs its length times the mean of the two cells' costs (:meth:`PlanGrid.
    padded_costs`: 1 in the open, more near obstacles); the octile distance stays an
    admissible heuristic since no cell costs less than 1. Diagonal steps may not cut the
    corner of a blocked cell. Flat indices into the padded grid and plain lists keep the inner
    loop in fast Python (no numpy scalar overhead).
    """
    if not grid.free(start) or not grid.free(goal):
        return None
    _, w = grid.shape
    stride = w + 2
    blocked = grid.padded_flat()
    costs = grid.padded_costs()
    s = (start[1] + 1) * stride + start[0] + 1
    g = (goal[1] + 1) * stride + goal[0] + 1
    gc, gr = goal[0] + 1, goal[1] + 1
    half_diag = _SQRT2 / 2.0
    steps = (
        (1, 0.5, 0, 0),
        (-1, 0.5, 0, 0),
        (stride, 0.5, 0, 0),
        (-stride, 0.5, 0, 0),
        (stride + 1, half_diag, 1, stride),
        (stride - 1, half_diag, -1, stride),
        (-stride + 1, half_diag, 1, -stride),
        (-stride - 1, half_diag, -1, -stride),
    )
    size = len(blocked)
    cost = [math.inf] * size
    cost[s] = 0.0
    parent = [-1] * size
    closed = bytearray(size)
    # A hair over the octile distance breaks ties toward the goal: far fewer expansions on
    # open floors, at a negligible cost in optimality.
    bias = 1.0 + 1e-3
    diagonal = (_SQRT2 - 2.0) * bias
    push, pop = heapq.heappush, heapq.heappop
    heap: list[tuple[float, float, int]] = [(0.0, 0.0, s)]
    while heap:
        _, cost_n, n = pop(heap)
        if closed[n]:
            continue
        if n == g:
            return _unwind(parent, n, s, stride)
        closed[n] = 1
        here = costs[n]
        for step, half, side_x, side_y in steps:
            m = n + step
            if blocked[m] or closed[m]:
                continue
            if side_x and (blocked[n + side_x] or blocked[n + side_y]):
                continue  # would cut a blocked corner
            new_cost = cost_n + half * (here + costs[m])
            if new_cost < cost[m]:
                cost[m] = new_cost
                parent[m] = n
                row, col = divmod(m, stride)
                dx = col - gc if col > gc else gc - col
                dy = row - gr if row > gr else gr - row
                h_cost = (dx + dy) * bias + diagonal * (dx if dx < dy else dy)
                push(heap, (new_cost + h_cost, new_cost, m))
    return None


def _unwind(parent: list[int], n: int, start: int, stride: int) -> list[Cell]:
    cells: list[Cell] = []
    while True:
        row, col = divmod(n, stride)
        cells.append((col - 1, row - 1))
        if n == start:
            break
        n = parent[n]
    cells.reverse()
    return cells


def _samples(
    grid: PlanGrid, a: tuple[float, float], b: tuple[float, float]
) -> tuple[np.ndarray[Any, np.dtype[np.int64]], np.ndarray[Any, np.dtype[np.int64]]] | None:
    """The cells under the straight line between fractional cell positions ``a`` and ``b``
    (sampled every quarter cell, which cannot skip a whole cell); None if it leaves the grid."""
    length = math.hypot(b[0] - a[0], b[1] - a[1])
    n = max(2, math.ceil(length * 4.0) + 1)
    t = np.linspace(0.0, 1.0, n)
    cols = np.floor(a[0] + t * (b[0] - a[0])).astype(np.int64)
    rows = np.floor(a[1] + t * (b[1] - a[1])).astype(np.int64)
    h, w = grid.shape
    if cols.min() < 0 or rows.min() < 0 or cols.max() >= w or rows.max() >= h:
        return None
    return cols, rows


def visible(
    grid: PlanGrid,
    a: tuple[float, float],
    b: tuple[float, float],
    clearance_m: float | np.ndarray[Any, np.dtype[np.float64]] = 0.0,
) -> bool:
    """True if the straight line between fractional cell positions ``a`` and ``b`` crosses no
    blocked cell, nor (with a clearance map) a cell whose clearance is below ``clearance_m``:
    one value for the whole line, or a profile of values evenly spaced from ``a`` to ``b``."""
    cells = _samples(grid, a, b)
    if cells is None:
        return False
    cols, rows = cells
    if grid.blocked[rows, cols].any():
        return False
    if grid.clearance is None:
        return True
    if isinstance(clearance_m, np.ndarray):
        at = np.linspace(0.0, 1.0, len(cols))
        need = np.interp(at, np.linspace(0.0, 1.0, len(clearance_m)), clearance_m)
        return bool(np.all(grid.clearance[rows, cols] >= need - 1e-9))
    if clearance_m > 0.0:
        return bool(grid.clearance[rows, cols].min() >= clearance_m - 1e-9)
    return True


def shortcut(grid: PlanGrid, cells: list[Cell]) -> list[Cell]:
    """Keep only the cells where the path must bend: straight segments, each as long as line
    of sight allows (found by galloping then bisecting along the path), then one pass that
    drops a kept cell whenever its two neighbours see each other.

    With a clearance map, a straight segment may replace a stretch of the path only if it keeps
    that stretch's clearance *where it replaces it*: at each point along the segment, no closer
    to an obstacle than the path was around the corresponding place (its smallest clearance
    within SHORTCUT_WINDOW_M along the path, less half a cell) or than ``cost_radius_m``
    (beyond which nothing costs). So a segment leaving a robot that stands near a wall may
    start near it, but cannot run along it; and round a corner the path stays as wide as A*
    made it, in a few shorter segments.
    """
    n = len(cells)
    if n <= 2:
        return list(cells)
    centre = [(c + 0.5, r + 0.5) for c, r in cells]
    local: np.ndarray[Any, np.dtype[np.float64]] | None = None
    if grid.costed:
        clear = np.array([min(grid.clearance_at(c), grid.cost_radius_m) for c in cells])
        w = max(1, round(SHORTCUT_WINDOW_M / grid.resolution))
        windows = np.lib.stride_tricks.sliding_window_view(np.pad(clear, w, mode="edge"), 2 * w + 1)
        local = windows.min(axis=1) - 0.5 * grid.resolution

    def sees(i: int, j: int) -> bool:
        need = local[i : j + 1] if local is not None else 0.0
        return visible(grid, centre[i], centre[j], need)

    kept = [0]
    anchor = 0
    while anchor < n - 1:
        good, bad, step = anchor + 1, n, 2  # anchor sees anchor + 1: they are neighbours
        while good < n - 1:
            j = min(anchor + step, n - 1)
            if not sees(anchor, j):
                bad = j
                break
            good, step = j, step * 2
        while bad - good > 1:
            mid = (good + bad) // 2
            if sees(anchor, mid):
                good = mid
            else:
                bad = mid
        kept.append(good)
        anchor = good
    k = 1
    while k < len(kept) - 1:
        if sees(kept[k - 1], kept[k + 1]):
            del kept[k]
        else:
            k += 1
    return [cells[i] for i in kept]


def nearest_free(grid: PlanGrid, cell: Cell, radius_cells: int) -> Cell | None:
    """The free cell closest to ``cell`` within ``radius_cells``, or None."""
    if grid.free(cell):
        return cell
    h, w = grid.shape
    c0, r0 = max(0, cell[0] - radius_cells), max(0, cell[1] - radius_cells)
    c1, r1 = min(w, cell[0] + radius_cells + 1), min(h, cell[1] + radius_cells + 1)
    if c0 >= c1 or r0 >= r1:
        return None
    window = ~grid.blocked[r0:r1, c0:c1]
    rows, cols = np.nonzero(window)
    if rows.size == 0:
        return None
    d2 = (cols + c0 - cell[0]) ** 2 + (rows + r0 - cell[1]) ** 2
    best = int(np.argmin(d2))
    if d2[best] > radius_cells * radius_cells:
        return None
    return int(cols[best] + c0), int(rows[best] + r0)


def plan_path(grid: PlanGrid, start: XY, goal: XY) -> list[XY] | None:
    """A shortcut world path from ``start`` to ``goal``, both included; None if blocked.

    A start or goal inside an inflated obstacle (a robot parked close to a wall, a goal next
    to a shelf) is moved to the nearest free cell within SNAP_RADIUS_M; the path still begins
    at the robot and ends at the exact goal, the short hop in between being the controllers'
    business.
    """
    snap = max(1, round(SNAP_RADIUS_M / grid.resolution))
    s_cell = nearest_free(grid, grid.cell_of(*start), snap)
    g_cell = nearest_free(grid, grid.cell_of(*goal), snap)
    if s_cell is None or g_cell is None:
        return None
    cells = astar(grid, s_cell, g_cell)
    if cells is None:
        return None
    inner = [grid.to_world(c) for c in shortcut(grid, cells)]
    # The first and last kept cells stand for the start and the goal themselves, unless they
    # were snapped away from them: then keep the snapped cell as a waypoint.
    points = [start, *inner[1:-1]] if s_cell == grid.cell_of(*start) else [start, *inner[:-1]]
    if g_cell != grid.cell_of(*goal) and len(inner) > 1:
        points.append(inner[-1])
    points.append(goal)
    return _dedupe(points)


def _dedupe(points: list[XY]) -> list[XY]:
    out = [points[0]]
    for p in points[1:]:
        if math.hypot(p[0] - out[-1][0], p[1] - out[-1][1]) > 1e-6:
            out.append(p)
    if len(out) == 1:
        out.append(points[-1])
    return out


def path_length(points: list[XY]) -> float:
    return sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in itertools.pairwise(points))

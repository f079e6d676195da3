"""Paths on the map table's occupancy grid: inflation, 8-connected A*, line-of-sight shortcut.

The grid comes from the ``map`` table (row 0 at the bottom, 0 free, 100 occupied, 255
unknown). Unknown counts as occupied: a robot should not plan through space nobody has seen.
Obstacles are inflated by the robot's footprint radius plus a margin so the robot's *centre*
can be planned as a point; the A* result is then shortcut with line-of-sight checks on the
same inflated grid, which turns the staircase of cells into a few straight segments.

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

# Cells at or above this value are obstacles: 100 (occupied) and 255 (unknown) in the
# trinary maps we ship, and "more likely occupied than not" in scaled ROS maps.
OCCUPIED_AT = 50
# Above this many cells the planning grid is coarsened (max-pooled), so one A* stays in the
# tens of milliseconds even on a large warehouse map.
MAX_PLAN_CELLS = 160_000
# How far (m) a start or goal inside an inflated obstacle may be moved to the nearest free cell.
SNAP_RADIUS_M = 0.6
_SQRT2 = math.sqrt(2.0)


def inflate(occupied: BoolGrid, radius_cells: float) -> BoolGrid:
    """Every cell whose centre is within ``radius_cells`` of an occupied cell's centre."""
    out = occupied.copy()
    reach = math.floor(radius_cells)
    if reach <= 0:
        return out
    h, w = occupied.shape
    padded = np.pad(occupied, reach, constant_values=False)
    limit = radius_cells * radius_cells + 1e-9
    for dy in range(-reach, reach + 1):
        for dx in range(-reach, reach + 1):
            if (dx or dy) and dx * dx + dy * dy <= limit:
                out |= padded[reach + dy : reach + dy + h, reach + dx : reach + dx + w]
    return out


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


@dataclass
class PlanGrid:
    """An inflated (maybe coarsened) grid in world coordinates, ready for A*."""

    blocked: BoolGrid
    resolution: float
    origin_x: float
    origin_y: float
    origin_yaw: float = 0.0
    _flat: list[bool] | None = field(default=None, repr=False)

    @property
    def shape(self) -> tuple[int, int]:
        h, w = self.blocked.shape
        return int(h), int(w)

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

    def inside(self, cell: Cell) -> bool:
        h, w = self.shape
        return 0 <= cell[0] < w and 0 <= cell[1] < h

    def free(self, cell: Cell) -> bool:
        return self.inside(cell) and not bool(self.blocked[cell[1], cell[0]])

    def padded_flat(self) -> list[bool]:
        """The grid with a one-cell blocked border, flattened: A* then needs no bounds test.
        Cached: converting to a Python list is the costly part and the grid never changes."""
        if self._flat is None:
            padded = np.pad(self.blocked, 1, constant_values=True)
            self._flat = padded.ravel().tolist()
        return self._flat


def plan_grid(
    occupied: BoolGrid,
    resolution: float,
    origin: tuple[float, float, float],
    inflation_m: float,
    max_cells: int = MAX_PLAN_CELLS,
) -> PlanGrid:
    """Inflate ``occupied`` by ``inflation_m``, then coarsen if the grid is too large."""
    blocked = inflate(occupied, inflation_m / resolution)
    factor = max(1, math.ceil(math.sqrt(blocked.size / max_cells)))
    return PlanGrid(coarsen(blocked, factor), resolution * factor, *origin)


def astar(grid: PlanGrid, start: Cell, goal: Cell) -> list[Cell] | None:
    """Shortest 8-connected cell path from ``start`` to ``goal``, or None if there is none.

    Diagonal steps may not cut the corner of a blocked cell. Flat indices into the padded grid
    and plain lists keep the inner loop in fast Python (no numpy scalar overhead).
    """
    if not grid.free(start) or not grid.free(goal):
        return None
    _, w = grid.shape
    stride = w + 2
    blocked = grid.padded_flat()
    s = (start[1] + 1) * stride + start[0] + 1
    g = (goal[1] + 1) * stride + goal[0] + 1
    gc, gr = goal[0] + 1, goal[1] + 1
    steps = (
        (1, 1.0, 0, 0),
        (-1, 1.0, 0, 0),
        (stride, 1.0, 0, 0),
        (-stride, 1.0, 0, 0),
        (stride + 1, _SQRT2, 1, stride),
        (stride - 1, _SQRT2, -1, stride),
        (-stride + 1, _SQRT2, 1, -stride),
        (-stride - 1, _SQRT2, -1, -stride),
    )
    cost: dict[int, float] = {s: 0.0}
    parent: dict[int, int] = {}
    closed = bytearray(len(blocked))
    # A hair over the octile distance breaks ties toward the goal: far fewer expansions on
    # open floors, at a negligible cost in optimality.
    bias = 1.0 + 1e-3
    heap: list[tuple[float, float, int]] = [(0.0, 0.0, s)]
    while heap:
        _, cost_n, n = heapq.heappop(heap)
        if closed[n]:
            continue
        if n == g:
            return _unwind(parent, n, s, stride)
        closed[n] = 1
        for step, length, side_x, side_y in steps:
            m = n + step
            if blocked[m] or closed[m]:
                continue
            if side_x and (blocked[n + side_x] or blocked[n + side_y]):
                continue  # would cut a blocked corner
            new_cost = cost_n + length
            if new_cost < cost.get(m, math.inf):
                cost[m] = new_cost
                parent[m] = n
                row, col = divmod(m, stride)
                dx, dy = abs(col - gc), abs(row - gr)
                h_cost = (dx + dy + (_SQRT2 - 2.0) * min(dx, dy)) * bias
                heapq.heappush(heap, (new_cost + h_cost, new_cost, m))
    return None


def _unwind(parent: dict[int, int], n: int, start: int, stride: int) -> list[Cell]:
    cells: list[Cell] = []
    while True:
        row, col = divmod(n, stride)
        cells.append((col - 1, row - 1))
        if n == start:
            break
        n = parent[n]
    cells.reverse()
    return cells


def visible(grid: PlanGrid, a: tuple[float, float], b: tuple[float, float]) -> bool:
    """True if the straight line between fractional cell positions ``a`` and ``b`` crosses no
    blocked cell (sampled every quarter cell, which cannot skip a whole cell)."""
    length = math.hypot(b[0] - a[0], b[1] - a[1])
    n = max(2, math.ceil(length * 4.0) + 1)
    t = np.linspace(0.0, 1.0, n)
    cols = np.floor(a[0] + t * (b[0] - a[0])).astype(np.int64)
    rows = np.floor(a[1] + t * (b[1] - a[1])).astype(np.int64)
    h, w = grid.shape
    if cols.min() < 0 or rows.min() < 0 or cols.max() >= w or rows.max() >= h:
        return False
    return not bool(grid.blocked[rows, cols].any())


def shortcut(grid: PlanGrid, cells: list[Cell]) -> list[Cell]:
    """Keep only the cells where the path must bend: greedy line-of-sight, one pass."""
    if len(cells) <= 2:
        return list(cells)
    centre = [(c + 0.5, r + 0.5) for c, r in cells]
    kept = [cells[0]]
    anchor = 0
    for i in range(2, len(cells)):
        if not visible(grid, centre[anchor], centre[i]):
            anchor = i - 1
            kept.append(cells[anchor])
    kept.append(cells[-1])
    return kept


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

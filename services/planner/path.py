"""Paths on the planning grid (grid.py): costed 8-connected A*, then a shortcut.

The A* staircase is straightened with line-of-sight checks that also keep the clearance: a
straight segment replaces a stretch of the path only if it comes no closer to an obstacle
than that stretch did (or than ``cost_radius_m``), so a shortcut never cuts back to the walls.

Everything here is pure (no database, no engine), so it is unit-tested on hand-made grids.
The grid's names are importable from here too (``from services.planner.path import PlanGrid``).
"""

from __future__ import annotations

import heapq
import itertools
import math
from typing import Any

import numpy as np

from services.planner.grid import (
    COST_RADIUS_M,
    COST_WEIGHT,
    MAX_PLAN_CELLS,
    OCCUPIED_AT,
    XY,
    BoolGrid,
    Cell,
    FloatGrid,
    PlanGrid,
    clearance_cells,
    coarsen,
    inflate,
    plan_grid,
    with_obstacles,
)

__all__ = [
    "COST_RADIUS_M",
    "COST_WEIGHT",
    "MAX_PLAN_CELLS",
    "OCCUPIED_AT",
    "SHORTCUT_WINDOW_M",
    "SNAP_RADIUS_M",
    "XY",
    "BoolGrid",
    "Cell",
    "FloatGrid",
    "PlanGrid",
    "astar",
    "clearance_cells",
    "coarsen",
    "inflate",
    "nearest_free",
    "path_length",
    "plan_grid",
    "plan_path",
    "shortcut",
    "visible",
    "with_obstacles",
]

# How far (m) a start or goal inside an inflated obstacle may be moved to the nearest free cell.
SNAP_RADIUS_M = 0.6
# A shortcut keeps, at each point, the path's clearance within this distance along the path.
SHORTCUT_WINDOW_M = 0.3
_SQRT2 = math.sqrt(2.0)


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

"""Where the robot fits, and the shortest way through: inflation, A*, line-of-sight shortcut.

Grids here are boolean arrays ``[row, col]`` with row 0 at the bottom (the map_server grid
after its flip), one cell per map pixel, and ``origin`` the world position of the lower-left
corner of cell (0, 0). A cell is *traversable* when a disc of the inflation radius centred on
the cell's centre overlaps no occupied cell. With a margin of at least half a cell diagonal
on top of the footprint radius, the robot's disc then fits anywhere inside a traversable
cell, so a polyline whose points all lie in traversable cells is a collision-free path.
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

BoolGrid = npt.NDArray[np.bool_]
Point = tuple[float, float]

SQRT2 = math.sqrt(2.0)
# Samples per cell along a segment tested for line of sight: fine enough that the disc at
# any point between two samples is still covered by the margin (see the module docstring).
LOS_SAMPLES_PER_CELL = 10


@dataclass(frozen=True)
class ReferencePath:
    """The shortest path found for the robot's centre, start to goal, in world metres."""

    points: tuple[Point, ...]
    length_m: float
    grid_length_m: float  # the 8-connected A* path's length, before the shortcut


def inflate(occupied: BoolGrid, resolution: float, radius_m: float) -> BoolGrid:
    """Cells whose centre lies closer than ``radius_m`` to an occupied cell's square; beyond
    the map's edge counts as occupied (the robot may not leave the map)."""
    reach = math.ceil(radius_m / resolution) + 1
    rows, cols = occupied.shape
    padded = np.ones((rows + 2 * reach, cols + 2 * reach), dtype=bool)
    padded[reach:-reach, reach:-reach] = occupied
    blocked = np.zeros_like(occupied)
    for dr in range(-reach, reach + 1):
        for dc in range(-reach, reach + 1):
            # distance from a cell centre to the nearest point of the square (dr, dc) away
            gap_x = max(abs(dc) - 0.5, 0.0) * resolution
            gap_y = max(abs(dr) - 0.5, 0.0) * resolution
            if math.hypot(gap_x, gap_y) < radius_m:
                blocked |= padded[reach + dr : reach + dr + rows, reach + dc : reach + dc + cols]
    return blocked


def astar(
    traversable: BoolGrid, start: tuple[int, int], goal: tuple[int, int]
) -> list[tuple[int, int]] | None:
    """The shortest 8-connected cell path (row, col) from ``start`` to ``goal``, or None.

    A diagonal step costs sqrt(2) and is allowed only when both cells beside it are
    traversable, so the segment between two cell centres never clips a blocked corner."""
    rows, cols = int(traversable.shape[0]), int(traversable.shape[1])
    free = traversable.ravel().tolist()  # plain lists: far faster than numpy scalars here
    s, g = start[0] * cols + start[1], goal[0] * cols + goal[1]
    if not (free[s] and free[g]):
        return None
    gr, gc = goal

    def heuristic(i: int) -> float:  # octile distance: exact on an empty grid, admissible
        dr, dc = abs(i // cols - gr), abs(i % cols - gc)
        return (SQRT2 - 1.0) * min(dr, dc) + max(dr, dc)

    cost = {s: 0.0}
    parent = {s: s}
    heap = [(heuristic(s), s)]
    done = set()
    while heap:
        _, i = heapq.heappop(heap)
        if i == g:
            break
        if i in done:
            continue
        done.add(i)
        for j, step in _steps(free, rows, cols, i):
            if j in done:
                continue
            new = cost[i] + step
            if new < cost.get(j, math.inf):
                cost[j] = new
                parent[j] = i
                heapq.heappush(heap, (new + heuristic(j), j))
    if g not in parent:
        return None
    cells = [g]
    while cells[-1] != s:
        cells.append(parent[cells[-1]])
    return [divmod(i, cols) for i in reversed(cells)]


_NEIGHBOURS = ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1))


def _steps(free: list[bool], rows: int, cols: int, i: int) -> list[tuple[int, float]]:
    """The traversable neighbours of cell ``i`` with the cost of the step to each; a
    diagonal only when both cells beside it are free (no clipped corner)."""
    r, c = divmod(i, cols)
    out = []
    for dr, dc in _NEIGHBOURS:
        nr, nc = r + dr, c + dc
        if not (0 <= nr < rows and 0 <= nc < cols) or not free[nr * cols + nc]:
            continue
        if dr and dc:
            if free[r * cols + nc] and free[nr * cols + c]:
                out.append((nr * cols + nc, SQRT2))
        else:
            out.append((nr * cols + nc, 1.0))
    return out


def world_to_cell(origin: Point, resolution: float, x: float, y: float) -> tuple[int, int]:
    """The (row, col) of the cell holding a world point (not checked against the grid)."""
    return math.floor((y - origin[1]) / resolution), math.floor((x - origin[0]) / resolution)


def cell_centre(origin: Point, resolution: float, row: int, col: int) -> Point:
    return origin[0] + (col + 0.5) * resolution, origin[1] + (row + 0.5) * resolution


def line_of_sight(
    traversable: BoolGrid, origin: Point, resolution: float, a: Point, b: Point
) -> bool:
    """Whether every point of segment a-b lies in a traversable cell (sampled finely)."""
    n = max(2, math.ceil(math.dist(a, b) / resolution * LOS_SAMPLES_PER_CELL) + 1)
    t = np.linspace(0.0, 1.0, n)
    cols = np.floor((a[0] + t * (b[0] - a[0]) - origin[0]) / resolution).astype(np.int64)
    rows = np.floor((a[1] + t * (b[1] - a[1]) - origin[1]) / resolution).astype(np.int64)
    height, width = traversable.shape
    if rows.min() < 0 or cols.min() < 0 or rows.max() >= height or cols.max() >= width:
        return False
    return bool(traversable[rows, cols].all())


def shortcut(
    traversable: BoolGrid, origin: Point, resolution: float, points: Sequence[Point]
) -> list[Point]:
    """String pulling: from each kept vertex, go straight to the last vertex ahead still in
    sight; then drop every vertex whose two neighbours see each other, until none is left.
    Neighbouring vertices of the input must see each other (an A* path's do)."""

    def sees(a: Point, b: Point) -> bool:
        return line_of_sight(traversable, origin, resolution, a, b)

    kept = [points[0]]
    i = 0
    while i < len(points) - 1:
        j = i + 1
        while j + 1 < len(points) and sees(points[i], points[j + 1]):
            j += 1
        kept.append(points[j])
        i = j
    changed = True
    while changed:
        changed = False
        k = 1
        while k < len(kept) - 1:
            if sees(kept[k - 1], kept[k + 1]):
                del kept[k]
                changed = True
            else:
                k += 1
    return kept


def polyline_length(points: Sequence[Point]) -> float:
    return sum(math.dist(a, b) for a, b in itertools.pairwise(points))


def reference_path(
    occupied: BoolGrid,
    resolution: float,
    origin: Point,
    start: Point,
    goal: Point,
    inflation_m: float,
) -> ReferencePath | None:
    """The shortest path for a robot whose disc, grown by the margin, is ``inflation_m`` in
    radius; None when there is none (or the start or goal itself is blocked).

    8-connected A* over the traversable cells, then the line-of-sight shortcut: the result is
    never longer than the A* path and within a few percent of the any-angle shortest path."""
    traversable = ~inflate(occupied, resolution, inflation_m)
    height, width = traversable.shape
    s_cell = world_to_cell(origin, resolution, *start)
    g_cell = world_to_cell(origin, resolution, *goal)
    for r, c in (s_cell, g_cell):
        if not (0 <= r < height and 0 <= c < width):
            return None
    cells = astar(traversable, s_cell, g_cell)
    if cells is None:
        return None
    # exact start and goal, cell centres between them: each step stays inside the 2 x 2 block
    # of its two cells, which are traversable (no corner cutting)
    raw = [start, *(cell_centre(origin, resolution, r, c) for r, c in cells[1:-1]), goal]
    if len(cells) == 1:
        raw = [start, goal]
    pulled = shortcut(traversable, origin, resolution, raw)
    return ReferencePath(
        points=tuple(pulled),
        length_m=polyline_length(pulled),
        grid_length_m=polyline_length(raw),
    )

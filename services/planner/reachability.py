"""Reachability: whether the map *proves* that a goal can never be reached.

Three proofs, each on the map alone with the keepout zones that apply to the robot (never
the lidar's unmapped obstacles, which move and may leave a way round):

- the goal is outside the map, and no free cell of it lies within the goal's tolerance;
- the goal is inside a keepout zone (the reason names it);
- the goal is inside an obstacle, or so close to one that no cell the robot's centre may
  occupy (clearance above the inflation radius, as the planning grid's free cells) lies
  within the goal's tolerance of it;
- no cell within the tolerance of the goal is connected, on the planning grid, to the free
  cell nearest the robot (the one A* starts from: a robot standing in the inflation by a
  wall is searched from there, as path.py plans). 8-connected steps that may not cut a
  blocked corner connect exactly what 4-connected ones do, so a breadth-first flood of
  4-neighbours decides it.

A goal within its tolerance (plus half a cell's diagonal: a cell counts if the goal could
be reached from anywhere in it) of a free cell counts as reachable. Everything here is pure.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

import services.planner.keepout as keepout
from common.contract.zones import Zone
from services.planner.grid import XY, PlanGrid, clearance_cells
from services.planner.path import SNAP_RADIUS_M, nearest_free
from services.planner.world_model import MapData


def _xy(x: float, y: float) -> str:
    return f"({x:.2f}, {y:.2f})"


def span(data: MapData) -> str:
    """Where the map lies, for people."""
    h, w = data.occupied.shape
    ox, oy, yaw = data.origin
    if yaw:
        return f"{w * data.resolution:.2f} x {h * data.resolution:.2f} m from {_xy(ox, oy)}"
    x1, y1 = ox + w * data.resolution, oy + h * data.resolution
    return f"x {ox:.2f} to {x1:.2f} m, y {oy:.2f} to {y1:.2f} m"


def _window(grid: PlanGrid, x: float, y: float, radius_m: float) -> tuple[slice, slice]:
    """The rows and columns of ``grid`` holding every cell within ``radius_m`` of (x, y)."""
    fc, fr = grid.to_cell(x, y)
    reach = radius_m / grid.resolution + 1.0
    h, w = grid.shape
    c0, c1 = max(0, math.floor(fc - reach)), min(w, math.ceil(fc + reach) + 1)
    r0, r1 = max(0, math.floor(fr - reach)), min(h, math.ceil(fr + reach) + 1)
    return slice(r0, max(r0, r1)), slice(c0, max(c0, c1))


def _within(
    grid: PlanGrid, x: float, y: float, radius_m: float, rows: slice, cols: slice
) -> np.ndarray[Any, np.dtype[np.bool_]]:
    """Which cells of the window are within ``radius_m`` of (x, y), plus half a cell's
    diagonal (the goal may be reached from anywhere in a cell)."""
    fc, fr = grid.to_cell(x, y)
    reach = radius_m / grid.resolution + math.sqrt(0.5)
    dc = np.arange(cols.start, cols.stop) + 0.5 - fc
    dr = np.arange(rows.start, rows.stop) + 0.5 - fr
    return np.asarray(dr[:, None] ** 2 + dc[None, :] ** 2 <= reach * reach, dtype=np.bool_)


def spot_problem(
    data: MapData,
    inflation_m: float,
    x: float,
    y: float,
    tol_m: float,
    keepouts: tuple[Zone, ...] = (),
) -> str | None:
    """Why the goal (x, y) is not a place the robot's centre can come within ``tol_m`` of:
    outside the map, inside one of ``keepouts`` (keepout zones: named), or inside (or too
    close to) an obstacle on the map or a keepout zone. None: it is."""
    zone = keepout.containing(keepouts, x, y)
    if zone is not None:
        return f"goal {_xy(x, y)} is inside keepout zone '{zone.name}'"
    occupied = data.occupied_with(keepouts)
    why = _spot_problem(data, occupied, inflation_m, x, y, tol_m)
    if why is None or occupied is data.occupied:
        return why
    if _spot_problem(data, data.occupied, inflation_m, x, y, tol_m) is not None:
        return why  # the map alone proves it
    reach = tol_m + inflation_m + data.resolution
    near = [
        z
        for z in keepouts
        if min(z.xs) - reach <= x <= max(z.xs) + reach
        and min(z.ys) - reach <= y <= max(z.ys) + reach
    ]
    return (
        f"goal {_xy(x, y)} is too close to keepout zone {keepout.names(near or keepouts)}: "
        f"the robot's centre cannot come within {tol_m:.2f} m of it"
    )


def _spot_problem(
    data: MapData,
    occupied: np.ndarray[Any, np.dtype[np.bool_]],
    inflation_m: float,
    x: float,
    y: float,
    tol_m: float,
) -> str | None:
    fine = PlanGrid(occupied, data.resolution, *data.origin)
    margin = math.floor(inflation_m / data.resolution) + 1
    rows, cols = _window(fine, x, y, tol_m + margin * data.resolution)
    window = occupied[rows, cols]
    if window.size:
        # The clearance in the window is exact for every cell within tol_m: their obstacles
        # within the inflation radius all lie inside it. Free as plan_grid frees a cell.
        reach = inflation_m / data.resolution
        distance = clearance_cells(window, margin)
        free = distance * distance > reach * reach + 1e-9
        if bool((free & _within(fine, x, y, tol_m, rows, cols)).any()):
            return None
    col, row = fine.cell_of(x, y)
    if not fine.inside((col, row)):
        return f"goal {_xy(x, y)} is outside the map (the map spans {span(data)})"
    if bool(occupied[row, col]):
        return f"goal {_xy(x, y)} is inside an obstacle on the map"
    return (
        f"goal {_xy(x, y)} is too close to an obstacle on the map: the robot's centre "
        f"cannot come within {tol_m:.2f} m of it"
    )


def cut_off(grid: PlanGrid, start: XY, goal: XY, tol_m: float) -> bool:
    """Whether the planning grid proves the goal unreachable from ``start``: the free cell
    nearest the start (within SNAP_RADIUS_M) exists and no free cell within ``tol_m`` of the
    goal is connected to it. No proof (False) when there is no such start or goal cell."""
    snap = max(1, round(SNAP_RADIUS_M / grid.resolution))
    start_cell = nearest_free(grid, grid.cell_of(*start), snap)
    rows, cols = _window(grid, goal[0], goal[1], tol_m)
    targets = _within(grid, goal[0], goal[1], tol_m, rows, cols) & ~grid.blocked[rows, cols]
    if start_cell is None or not targets.any():
        return False
    _, w = grid.shape
    stride = w + 2
    blocked = grid.padded_flat()
    wanted = bytearray(len(blocked))
    for r, c in zip(*np.nonzero(targets), strict=True):
        wanted[(int(r) + rows.start + 1) * stride + int(c) + cols.start + 1] = 1
    first = (start_cell[1] + 1) * stride + start_cell[0] + 1
    seen = bytearray(len(blocked))
    seen[first] = 1
    queue = deque([first])
    steps = (1, -1, stride, -stride)
    while queue:
        n = queue.popleft()
        if wanted[n]:
            return False
        for step in steps:
            m = n + step
            if not seen[m] and not blocked[m]:
                seen[m] = 1
                queue.append(m)
    return True

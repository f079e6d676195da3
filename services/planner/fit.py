"""Whether a robot's footprint polygon fits along a planned path, and a path that does.

A* plans the robot's centre as a point on a grid blocked within the footprint's *inscribed*
radius (plus the inflation margin) of every obstacle: the least room the robot needs,
whatever its heading. Inflating by the circumscribed radius instead would be safe at any
heading, but shuts a box out of every gap it fits straight on (a Jackal's corners reach
0.333 m; its sides 0.215 m). The heading is known along a path, so the inscribed plan is
checked: the footprint at poses along each leg (heading along it), and at each corner at the
headings it turns through in place (common.collision.path_poses), against the map's own cells
and the unmapped obstacles seen (common.collision's checks, the same the sim's contact test
agrees with). Where a pose collides, its cell is blocked and A* runs again, up to
MAX_REFITS times; then the plan falls back to the circumscribed inflation, which fits at any
heading; when even that finds no way, the inscribed path stands (a robot that turns while
it drives may still get through; the safety layer and the sim judge every move).

A disc needs none of this: its inscribed and circumscribed radii are one.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from common.collision import collides_on_grid, collides_with_points, path_poses
from common.footprint import Footprint
from services.planner.grid import XY, PlanGrid
from services.planner.obstacles import Points
from services.planner.world_model import MapData

MAX_REFITS = 8  # collisions blocked and planned around before the circumscribed fallback
FIT_MARGIN_M = 0.02  # clearance the polygon keeps from obstacles along the path, m
# poses this close to the start or the goal are not checked: the robot stands at the one
# and stops within tolerance of the other, and blocking either would leave no path
ENDS_M = 0.1

Pose = tuple[float, float, float]
Planner = Callable[[PlanGrid, XY, XY], list[XY] | None]


def collision(
    footprint: Footprint,
    points: list[XY],
    data: MapData,
    grid: PlanGrid,
    obstacles: Points | None = None,
) -> Pose | None:
    """The first pose along ``points`` at which the footprint meets the map or an obstacle
    (None: it fits all the way)."""
    step = max(data.resolution, 0.05)
    start, goal = points[0], points[-1]
    # beyond this clearance (the grid's, capped but far above it) nothing can be met
    safe = footprint.circumscribed_m + FIT_MARGIN_M + grid.resolution
    ox, oy, oyaw = data.origin
    c, s = math.cos(oyaw), math.sin(oyaw)
    # at a corner, headings close enough that no corner moves more than a step between them
    for pose in path_poses(points, step, step / footprint.circumscribed_m):
        x, y, yaw = pose
        if math.dist((x, y), start) < ENDS_M or math.dist((x, y), goal) < ENDS_M:
            continue
        cell = grid.cell_of(x, y)
        if grid.inside(cell) and grid.clearance_at(cell) >= safe:
            continue
        # the pose in the map's own frame, where its cells are axis-aligned
        dx, dy = x - ox, y - oy
        local = (c * dx + s * dy, -s * dx + c * dy, yaw - oyaw)
        if collides_on_grid(
            footprint, local, data.occupied, data.resolution, (0.0, 0.0), FIT_MARGIN_M
        ):
            return pose
        if obstacles is not None and collides_with_points(footprint, pose, obstacles, FIT_MARGIN_M):
            return pose
    return None


def fitted(
    footprint: Footprint,
    points: list[XY],
    data: MapData,
    grid: PlanGrid,
    wide: Callable[[], PlanGrid],
    plan: Planner,
    obstacles: Points | None = None,
) -> tuple[list[XY], str]:
    """A path from ``points[0]`` to ``points[-1]`` the footprint fits along (see the module),
    and how it was found: "fits", "refitted", "circumscribed" or "unfitted". ``wide`` gives
    the grid inflated by the circumscribed radius (built only when needed)."""
    start, goal = points[0], points[-1]
    current, how = points, "fits"
    for _ in range(MAX_REFITS):
        pose = collision(footprint, current, data, grid, obstacles)
        if pose is None:
            return current, how
        grid = _blocked_at(grid, pose)
        again = plan(grid, start, goal)
        if again is None:
            break
        current, how = again, "refitted"
    fallback = plan(wide(), start, goal)
    if fallback is not None:
        return fallback, "circumscribed"
    return points, "unfitted"


def _blocked_at(grid: PlanGrid, pose: Pose) -> PlanGrid:
    """A copy of ``grid`` with the cells round the one under ``pose`` blocked (a 3 x 3
    square: A* then moves off by more than the cell it was refused)."""
    col, row = grid.cell_of(pose[0], pose[1])
    if not grid.inside((col, row)):
        return grid
    blocked = grid.blocked.copy()
    blocked[max(0, row - 1) : row + 2, max(0, col - 1) : col + 2] = True
    clearance = None if grid.clearance is None else np.array(grid.clearance, copy=True)
    return grid.with_cells(blocked, clearance)

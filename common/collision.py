"""A footprint against the world: occupancy grids, scan returns, the poses along a path.

The planner's path check, the sim's tests and local planners all judge "does the robot touch
something here" with these, so they agree with each other; tests/unit/sim/
test_footprint_gap.py holds them to the sim's own contact test (pybullet), pose by pose.
The footprint itself, its radii and its outline's geometry are in common/footprint.py.

- :func:`collides_on_grid`: the footprint at a pose against an occupancy grid (each cell
  the square it stands for), within a margin;
- :func:`collides_with_points`: against points (a scan's returns in the world frame,
  obstacles), within a margin;
- :func:`square_gaps`: the gap to each of a set of squares (what the grid check weighs);
- :func:`path_poses`: the poses a path puts the robot in, turns in place included;
- :func:`first_contact`: the first of a roll-out's poses at which the footprint meets a
  scan's returns (what a local planner scoring trajectories asks).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from common.footprint import TURN_STEP_RAD, FloatArray, Footprint


def collides_with_points(
    footprint: Footprint,
    pose: tuple[float, float, float],
    points: FloatArray,
    margin_m: float = 0.0,
) -> bool:
    """Whether any of ``points`` (k x 2, world frame: a scan's returns, obstacle centres) lies
    inside the footprint at ``pose``, or within ``margin_m`` of its outline."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if not len(pts):
        return False
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    dx, dy = pts[:, 0] - x, pts[:, 1] - y
    near = dx * dx + dy * dy <= (footprint.circumscribed_m + margin_m) ** 2
    if not np.any(near):
        return False
    local = np.stack([c * dx[near] + s * dy[near], -s * dx[near] + c * dy[near]], axis=1)
    return bool(np.any(footprint.clearance(local) <= margin_m))


def collides_on_grid(
    footprint: Footprint,
    pose: tuple[float, float, float],
    occupied: npt.NDArray[np.bool_],
    resolution: float,
    origin: tuple[float, float],
    margin_m: float = 0.0,
) -> bool:
    """Whether the footprint at ``pose`` comes within ``margin_m`` of (or overlaps) an occupied
    cell of ``occupied`` (rows x cols, row 0 at ``origin``'s y, axis-aligned; cells off the
    grid are free). Each cell is the square it stands for, as the sim's walls are: the gap is
    the least of the square's corners' clearance from the outline and the outline's vertices'
    distance to the square, exact for a footprint wider than a cell."""
    x, y, _ = pose
    reach = footprint.circumscribed_m + margin_m + resolution
    ox, oy = origin
    c0 = max(0, math.floor((x - reach - ox) / resolution))
    c1 = min(occupied.shape[1] - 1, math.floor((x + reach - ox) / resolution))
    r0 = max(0, math.floor((y - reach - oy) / resolution))
    r1 = min(occupied.shape[0] - 1, math.floor((y + reach - oy) / resolution))
    if c0 > c1 or r0 > r1:
        return False
    rows, cols = np.nonzero(occupied[r0 : r1 + 1, c0 : c1 + 1])
    if not len(rows):
        return False
    half = resolution / 2.0
    centres = np.stack(
        [ox + (cols + c0 + 0.5) * resolution, oy + (rows + r0 + 0.5) * resolution], axis=1
    )
    return bool(np.any(square_gaps(footprint, pose, centres, half) <= margin_m))


def square_gaps(
    footprint: Footprint, pose: tuple[float, float, float], centres: FloatArray, half: float
) -> FloatArray:
    """The gap (m; <= 0: they overlap) between the footprint at ``pose`` and each
    axis-aligned square of half side ``half`` centred on ``centres`` (k x 2, world frame)."""
    x, y, yaw = pose
    if footprint.is_disc:
        dx = np.maximum(np.abs(centres[:, 0] - x) - half, 0.0)
        dy = np.maximum(np.abs(centres[:, 1] - y) - half, 0.0)
        disc: FloatArray = np.hypot(dx, dy) - footprint.radius_m
        return disc
    c, s = math.cos(yaw), math.sin(yaw)
    corners = (centres[:, None, :] + _CORNERS[None, :, :] * half).reshape(-1, 2)
    rel = corners - (x, y)
    local = np.stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]], axis=1)
    from_corners = np.min(footprint.clearance(local).reshape(-1, 4), axis=1)
    verts = footprint.at(x, y, yaw)  # n x 2
    dx = np.maximum(np.abs(verts[None, :, 0] - centres[:, 0:1]) - half, 0.0)
    dy = np.maximum(np.abs(verts[None, :, 1] - centres[:, 1:2]) - half, 0.0)
    from_vertices = np.min(np.hypot(dx, dy), axis=1)
    gaps: FloatArray = np.minimum(from_corners, from_vertices)
    return gaps


_CORNERS = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])


def path_poses(
    points: Sequence[tuple[float, float]], step_m: float, turn_step_rad: float = TURN_STEP_RAD
) -> list[tuple[float, float, float]]:
    """Poses along a path of points, heading along each leg, ``step_m`` apart at most, and at
    each corner the headings a robot turning in place there passes (``turn_step_rad`` apart:
    ``step_m / circumscribed radius`` moves no corner farther than ``step_m``): what the
    planner checks the footprint at."""
    out: list[tuple[float, float, float]] = []
    previous: float | None = None
    for (x0, y0), (x1, y1) in itertools.pairwise(points):
        length = math.hypot(x1 - x0, y1 - y0)
        if length == 0:
            continue
        yaw = math.atan2(y1 - y0, x1 - x0)
        if previous is not None:
            turn = math.remainder(yaw - previous, 2.0 * math.pi)
            k = int(abs(turn) // turn_step_rad)
            out += [(x0, y0, previous + turn * (i + 1) / (k + 1)) for i in range(k)]
        n = max(1, math.ceil(length / step_m))
        out += [(x0 + (x1 - x0) * i / n, y0 + (y1 - y0) * i / n, yaw) for i in range(n + 1)]
        previous = yaw
    return out


def first_contact(
    footprint: Footprint, poses: FloatArray, points: FloatArray, margin_m: float = 0.0
) -> int | None:
    """The index of the first of ``poses`` (k x 3: x, y, yaw, e.g. a roll-out's, in the frame
    of ``points``) at which the footprint comes within ``margin_m`` of one of ``points``
    (n x 2: a scan's returns in the robot's frame); None when none does. One pass for all
    poses: each pose's points near enough to matter (within the circumscribed radius plus
    the margin) are tested against the outline."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    ps = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    if not len(pts) or not len(ps):
        return None
    reach = footprint.circumscribed_m + margin_m
    dx = pts[None, :, 0] - ps[:, None, 0]  # k x n
    dy = pts[None, :, 1] - ps[:, None, 1]
    near = dx * dx + dy * dy <= reach * reach
    k, j = np.nonzero(near)
    if not len(k):
        return None
    c, s = np.cos(ps[k, 2]), np.sin(ps[k, 2])
    local = np.stack([c * dx[k, j] + s * dy[k, j], -s * dx[k, j] + c * dy[k, j]], axis=1)
    hit = footprint.clearance(local) <= margin_m
    return int(k[hit].min()) if hit.any() else None

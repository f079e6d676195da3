"""What a learned scenario sees of one decision, as numbers: one definition for the
dataset that trains a model (``pnav learn dataset``) and the scenario that runs it, so the
two can never disagree.

Everything is in the robot's frame (x ahead, y left) at the odometry's pose:

- ``sector_00`` .. ``sector_15``: the nearest lidar hit in each of 16 equal sectors, sector
  0 starting straight behind (-pi) and turning counter-clockwise, so sector 8 starts dead
  ahead; capped at ``RANGE_CAP_M`` (a sector with no hit, or no beam, reads the cap);
- ``linear_mps``, ``angular_rps``: the odometry's speed;
- ``carrot_x``, ``carrot_y``: the first point of the planned path at least ``CARROT_M``
  beyond the path point nearest the robot (the target if the path ends sooner);
- ``target_dist``, ``target_bearing``: the path's end, as distance and bearing (rad).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

SECTORS = 16
RANGE_CAP_M = 3.5  # the Burger's lidar range; farther hits tell a local policy nothing
CARROT_M = 0.6

SECTOR_NAMES = tuple(f"sector_{i:02d}" for i in range(SECTORS))
FEATURES: tuple[str, ...] = (
    *SECTOR_NAMES,
    "linear_mps",
    "angular_rps",
    "carrot_x",
    "carrot_y",
    "target_dist",
    "target_bearing",
)

FloatArray = np.ndarray[tuple[int, ...], np.dtype[np.float64]]


@functools.lru_cache(maxsize=8)
def _sectors_of(
    angle_min: float, angle_increment: float, count: int
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """For a lidar's beams: their order by sector, where each sector with beams starts in
    that order, and which sectors those are (the same for every scan of one lidar, so the
    sorting is done once, not per decision)."""
    angles = angle_min + angle_increment * np.arange(count)
    wrapped = (angles + math.pi) % (2.0 * math.pi)  # 0 .. 2 pi from straight behind
    index = np.minimum((wrapped / (2.0 * math.pi) * SECTORS).astype(np.int64), SECTORS - 1)
    order = np.argsort(index, kind="stable")
    present, starts = np.unique(index[order], return_index=True)
    return order, starts, present


def sector_minima(
    ranges: Sequence[float] | np.ndarray, angle_min: float, angle_increment: float
) -> FloatArray:
    """The nearest hit per sector (``SECTORS`` of them, from -pi), capped at RANGE_CAP_M."""
    r = np.asarray(ranges, dtype=np.float64)
    out = np.full(SECTORS, RANGE_CAP_M)
    if r.size == 0:
        return out
    order, starts, present = _sectors_of(float(angle_min), float(angle_increment), r.size)
    r = np.where(np.isfinite(r), np.minimum(r, RANGE_CAP_M), RANGE_CAP_M)
    out[present] = np.minimum.reduceat(r[order], starts)
    return out


def to_robot_frame(x: float, y: float, pose: tuple[float, float, float]) -> tuple[float, float]:
    """World point (x, y) in the frame of the robot at ``pose`` (x, y, yaw)."""
    dx, dy = x - pose[0], y - pose[1]
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return c * dx + s * dy, -s * dx + c * dy


def carrot(
    xs: Sequence[float], ys: Sequence[float], pose: tuple[float, float, float]
) -> tuple[float, float]:
    """The path point CARROT_M beyond the point nearest the robot, robot frame."""
    px, py = np.asarray(xs, dtype=np.float64), np.asarray(ys, dtype=np.float64)
    gap = np.hypot(px - pose[0], py - pose[1])
    nearest = int(np.argmin(gap))
    ahead = np.nonzero(gap[nearest:] >= CARROT_M)[0]
    i = nearest + int(ahead[0]) if ahead.size else px.size - 1
    return to_robot_frame(float(px[i]), float(py[i]), pose)


def features(
    sectors: FloatArray,
    speed: tuple[float, float],
    pose: tuple[float, float, float],
    xs: Sequence[float],
    ys: Sequence[float],
) -> FloatArray:
    """One decision's feature vector, in the order of FEATURES. ``xs``, ``ys``: the path
    in force, world frame, not empty."""
    cx, cy = carrot(xs, ys, pose)
    tx, ty = to_robot_frame(float(xs[-1]), float(ys[-1]), pose)
    tail = [speed[0], speed[1], cx, cy, math.hypot(tx, ty), math.atan2(ty, tx)]
    return np.concatenate([sectors, np.asarray(tail, dtype=np.float64)])

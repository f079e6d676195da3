"""A Jackal's lidar cast exactly into a small world of discs (movers, posts), boxes and
walls, for the dodge scenario's tests: the scan geometry the robot really gets (720 beams
over 270 degrees, range 0.1 to 30 m), worked out ray by ray with no sim in the loop."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from common.contract.records import LaserScan, Odometry, Robot

JACKAL = Robot("r1", 2.0, 4.0, 0.22, 270.0, max_linear_accel_mps2=10.0, max_angular_accel_rps2=20.0)
# the Jackal as its true box (models/jackal.yaml): 0.508 x 0.430 m, corners 0.333 m out
JACKAL_BOX = Robot(
    "r1",
    2.0,
    4.0,
    0.22,
    270.0,
    max_linear_accel_mps2=10.0,
    max_angular_accel_rps2=20.0,
    footprint_polygon=((0.254, -0.215), (0.254, 0.215), (-0.254, 0.215), (-0.254, -0.215)),
)
BEAMS = 720
ANGLE_MIN = -math.radians(135.0)
INCREMENT = math.radians(270.0) / (BEAMS - 1)


@dataclass(frozen=True)
class Disc:
    """A cylinder at (x, y) moving at (vx, vy) m/s from t = 0."""

    x: float
    y: float
    radius: float
    vx: float = 0.0
    vy: float = 0.0

    def at(self, t: float) -> tuple[float, float]:
        return self.x + self.vx * t, self.y + self.vy * t


Segment = tuple[float, float, float, float]  # a wall from (x0, y0) to (x1, y1)


def box(x: float, y: float, half: float) -> list[Segment]:
    """A square box's four sides."""
    c = [(x - half, y - half), (x + half, y - half), (x + half, y + half), (x - half, y + half)]
    return [(*c[i], *c[(i + 1) % 4]) for i in range(4)]


def cast(
    pose: tuple[float, float, float], discs: list[Disc], walls: list[Segment], t: float
) -> np.ndarray:
    """The ranges (inf: nothing within 30 m) from ``pose`` at sim time ``t``."""
    ox, oy, yaw = pose
    a = yaw + ANGLE_MIN + INCREMENT * np.arange(BEAMS)
    dx, dy = np.cos(a), np.sin(a)
    best = np.full(BEAMS, np.inf)
    for d in discs:
        cx, cy = d.at(t)
        fx, fy = ox - cx, oy - cy
        b = fx * dx + fy * dy
        c = fx * fx + fy * fy - d.radius**2
        disc = b * b - c
        hit = disc >= 0
        r = -b - np.sqrt(np.where(hit, disc, 0.0))
        best = np.where(hit & (r > 0) & (r < best), r, best)
    for x0, y0, x1, y1 in walls:
        ex, ey = x1 - x0, y1 - y0
        den = dx * ey - dy * ex
        with np.errstate(divide="ignore", invalid="ignore"):
            r = ((x0 - ox) * ey - (y0 - oy) * ex) / den
            u = ((x0 - ox) * dy - (y0 - oy) * dx) / den
        hit = (np.abs(den) > 1e-12) & (r > 0) & (u >= 0) & (u <= 1)
        best = np.where(hit & (r < best), r, best)
    best[best > 30.0] = np.inf
    return np.maximum(best, 0.1)


def scan_at(
    pose: tuple[float, float, float],
    discs: list[Disc],
    walls: list[Segment],
    t: float,
    scan_id: int,
) -> LaserScan:
    return LaserScan(
        id=scan_id,
        robot_id="r1",
        stamp=t,
        angle_min=ANGLE_MIN,
        angle_increment=INCREMENT,
        range_min=0.1,
        range_max=30.0,
        ranges=cast(pose, discs, walls, t).astype(np.float32),
    )


def odom_at(
    pose: tuple[float, float, float], v: float, w: float, t: float, odom_id: int
) -> Odometry:
    return Odometry(odom_id, "r1", t, pose[0], pose[1], pose[2], v, w)

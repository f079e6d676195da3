"""Synthetic scans, odometry and robots for the controller's unit tests."""

from __future__ import annotations

import math

import numpy as np

from common.contract.records import LaserScan, Odometry, Robot

BEAMS = 360
BURGER = Robot(
    "r1",
    max_linear_mps=0.22,
    max_angular_rps=2.84,
    footprint_radius_m=0.105,
    battery_capacity_wh=19.98,
)

Obstacle = tuple[float, float, float]  # (from deg, to deg, range m), in (-180, 180], CCW


def scan(
    *obstacles: Obstacle,
    scan_id: int = 1,
    stamp: float = 10.0,
    noise: float = 0.0,
    seed: int = 0,
) -> LaserScan:
    """A TurtleBot3-like sweep (beam 0 ahead, 1 deg apart, CCW), inf except the obstacles."""
    ranges = np.full(BEAMS, np.inf)
    beam_deg = np.arange(BEAMS, dtype=np.float64)
    angles = np.where(beam_deg > 180.0, beam_deg - 360.0, beam_deg)  # (-180, 180]
    for low, high, distance in obstacles:
        mask = (angles >= low) & (angles <= high)
        ranges[mask] = np.minimum(ranges[mask], distance)
    if noise:
        ranges = ranges + np.random.default_rng(seed).normal(0.0, noise, BEAMS)
    return LaserScan(
        id=scan_id,
        robot_id="r1",
        stamp=stamp,
        angle_min=0.0,
        angle_increment=2 * math.pi / BEAMS,
        range_min=0.12,
        range_max=3.5,
        ranges=ranges.astype(np.float32),
    )


def aisle(
    left_m: float, right_m: float, heading_deg: float = 0.0, *extra: Obstacle, noise: float = 0.0
) -> LaserScan:
    """A sweep between two long parallel walls, ``left_m`` to the left of the robot's centre
    and ``right_m`` to its right, the robot heading ``heading_deg`` (CCW) off the aisle's
    direction; plus any ``extra`` obstacles, as for :func:`scan`."""
    base = scan(*extra, noise=noise)
    ranges = np.asarray(base.ranges, dtype=np.float64)
    angles = np.radians(np.arange(BEAMS, dtype=np.float64)) + math.radians(heading_deg)
    with np.errstate(divide="ignore"):
        sin = np.sin(angles)
        walls = np.where(sin > 1e-9, left_m / sin, np.where(sin < -1e-9, -right_m / sin, np.inf))
    walls = np.where(walls <= 3.5, walls, np.inf)
    return LaserScan(
        id=base.id,
        robot_id=base.robot_id,
        stamp=base.stamp,
        angle_min=base.angle_min,
        angle_increment=base.angle_increment,
        range_min=base.range_min,
        range_max=base.range_max,
        ranges=np.minimum(ranges, walls).astype(np.float32),
    )


def odom(
    linear: float = 0.0, angular: float = 0.0, odom_id: int = 1, stamp: float = 10.0
) -> Odometry:
    return Odometry(odom_id, "r1", stamp, 0.0, 0.0, 0.0, linear, angular)

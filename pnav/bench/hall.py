"""The latency benchmark's world: a hall of straight lanes, one robot per lane, for any N.

Each robot shuttles between the two ends of its own lane (LANE_M long), so N robots keep
moving for as long as the benchmark runs without meeting each other. Every other lane has an
unmapped post slightly off its centre line: the planner cannot know it, so the controller's
lidar scenarios meet it on every pass and both sensor paths (odometry -> planner, laser scan
-> controller) carry commands.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from services.sim.mapserver import map_yaml, write_pgm

RES = 0.05
LANE_M = 4.0  # distance between a lane's two goals
LANE_GAP_M = 1.4  # between neighbouring lanes (side by side)
COLUMN_M = LANE_M + 2.0  # a column of lanes, with room to turn at both ends
ROWS = 10  # lanes per column
WALL_M = 0.1
POST_M = 0.18  # side of the square unmapped post
FREE, OCCUPIED = 254, 0


@dataclass(frozen=True)
class Lane:
    robot_id: str
    a: tuple[float, float]  # start, and the goal of every even leg
    b: tuple[float, float]  # the goal of every odd leg


@dataclass(frozen=True)
class Hall:
    world: Path
    lanes: tuple[Lane, ...]


def lanes(robots: int) -> tuple[Lane, ...]:
    out = []
    for i in range(robots):
        col, row = divmod(i, ROWS)
        x0 = 1.0 + col * COLUMN_M
        y = 0.8 + row * LANE_GAP_M
        out.append(Lane(f"r{i + 1}", (x0, y), (x0 + LANE_M, y)))
    return tuple(out)


def write_hall(directory: Path, robots: int) -> Hall:
    """Write the hall for ``robots`` robots into ``directory``; the world file's path."""
    if robots < 1:
        raise ValueError("the hall needs at least one robot")
    directory.mkdir(parents=True, exist_ok=True)
    all_lanes = lanes(robots)
    cols = math.ceil(robots / ROWS)
    rows = min(robots, ROWS)
    width = cols * COLUMN_M
    height = 0.8 * 2 + (rows - 1) * LANE_GAP_M
    w, h = round((width + 2 * WALL_M) / RES), round((height + 2 * WALL_M) / RES)
    pixels = np.full((h, w), OCCUPIED, dtype=np.uint8)
    wall = round(WALL_M / RES)
    pixels[wall : h - wall, wall : w - wall] = FREE
    # map_server images are stored top row first
    write_pgm(directory / "hall.pgm", pixels[::-1].copy())
    (directory / "hall_map.yaml").write_text(map_yaml("hall.pgm", RES, -WALL_M, -WALL_M))
    robot_lines = [
        f"  - {{id: {ln.robot_id}, x: {ln.a[0]}, y: {ln.a[1]}, yaw: 0.0}}" for ln in all_lanes
    ]
    posts = [
        f"  - {{name: post{i + 1}, type: box, x: {ln.a[0] + LANE_M / 2:.3f}, "
        f"y: {ln.a[1] + 0.12:.3f}, yaw: 0.0, size: [{POST_M}, {POST_M}, 0.4]}}"
        for i, ln in enumerate(all_lanes)
        if i % 2 == 1
    ]
    text = [
        f"# written by pnav bench latency: {robots} robots in lanes {LANE_M} m long",
        f"name: hall{robots}",
        "map: hall_map.yaml",
        "robots:",
        *robot_lines,
        "charging_stations:",
        f"  - {{id: dock1, x: {width - 0.4:.3f}, y: {height - 0.4:.3f}, radius: 0.3, power: 20.0}}",
    ]
    if posts:
        text += ["obstacles:", *posts]
    world = directory / f"hall{robots}.yaml"
    world.write_text("\n".join(text) + "\n")
    return Hall(world, all_lanes)

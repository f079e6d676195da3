"""Benchmark: what keepout and speed zones cost the planner and the bridge's safety layer.

``python -m pnav.bench.zone_cost [--world warehouse] [--repeat N] [--json FILE]`` prints, on the
world's map and the Burger's footprint:

- the planning grid built with 0, 1, 16 and 256 keepout zones (the table's bound), small
  ones (1 m squares spread over the map) and the worst a person may write (100-vertex
  polygons as large as the map): what a zone change costs the planner, once per change;
- one A* plan across the map on the grid with the small zones (a route round them);
- one safety-layer verdict with 0, 16 and 256 speed zones of 100 vertices, the robot's centre
  outside every zone's box (the common case) and inside all of them (the worst).

Best of ``--repeat`` passes each (wall ms), so a loaded machine's noise shows less.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from common.contract.zones import KEEPOUT, SPEED_LIMIT, Zone
from pnav.bench.figures import emit, machine
from pnav.run.launcher import resolve_world
from services.bridge.safety import SafetyLayer, SafetyParams
from services.bridge.sensor_payloads import LaserScan
from services.planner.keepout import Keepouts
from services.planner.path import plan_path
from services.planner.world_model import MapData
from services.sim.world_spec import load_world

FOOTPRINT_M = 0.105  # the Burger's


def best_ms(work: Callable[[], Any], repeat: int) -> float:
    best = math.inf
    for _ in range(repeat):
        started = time.perf_counter()
        work()
        best = min(best, time.perf_counter() - started)
    return round(best * 1000, 3)


def big_polygon(box: tuple[float, float, float, float], n: int, phase: float) -> Zone:
    """A 100-vertex star as large as the box (simple: vertices in angle order)."""
    x0, y0, x1, y1 = box
    cx, cy, rx, ry = (x0 + x1) / 2, (y0 + y1) / 2, (x1 - x0) / 2, (y1 - y0) / 2
    angles = np.linspace(0, 2 * np.pi, n, endpoint=False) + phase
    radii = np.where(np.arange(n) % 2 == 0, 1.0, 0.8)
    xs = tuple(float(v) for v in cx + rx * radii * np.cos(angles))
    ys = tuple(float(v) for v in cy + ry * radii * np.sin(angles))
    return Zone(f"big{phase:.3f}", KEEPOUT, xs, ys)


def small_squares(box: tuple[float, float, float, float], count: int) -> list[Zone]:
    x0, y0, x1, y1 = box
    rng = np.random.default_rng(11)
    out = []
    for i in range(count):
        x, y = rng.uniform(x0, x1 - 1.0), rng.uniform(y0, y1 - 1.0)
        xs, ys = (x, x + 1.0, x + 1.0, x), (y, y, y + 1.0, y + 1.0)
        out.append(Zone(f"sq{i}", KEEPOUT, xs, ys))
    return out


def planner_figures(data: MapData, repeat: int) -> dict[str, Any]:
    h, w = data.occupied.shape
    ox, oy, _ = data.origin
    box = (ox, oy, ox + w * data.resolution, oy + h * data.resolution)
    out: dict[str, Any] = {"map_cells": int(h * w)}
    for count in (0, 1, 16, 256):
        for kind, zones in (
            ("small", small_squares(box, count)),
            ("map-sized 100-vertex", [big_polygon(box, 100, i / 1000) for i in range(count)]),
        ):
            keepouts = Keepouts(zones)

            def build(k: Keepouts = keepouts) -> None:
                fresh = MapData(
                    data.map_id, data.version, data.occupied, data.resolution, data.origin
                )
                fresh.grid(FOOTPRINT_M, k)

            out[f"grid with {count} {kind} keepout zones, ms"] = best_ms(build, repeat)
            if count == 0:
                break
    squares = Keepouts(small_squares(box, 16))
    grid = data.grid(FOOTPRINT_M, squares)
    start, goal = (box[0] + 1.0, box[1] + 2.5), (box[2] - 1.0, box[3] - 1.5)
    out["A* across the map round 16 small zones, ms"] = best_ms(
        lambda: plan_path(grid, start, goal), repeat
    )
    return out


def bridge_figures(repeat: int) -> dict[str, Any]:
    out: dict[str, Any] = {}
    box = (0.0, 0.0, 20.0, 20.0)
    scan = LaserScan("r1", 10.0, 0, 0.0, 2 * math.pi / 360, 0.12, 3.5, [math.inf] * 360)
    for count in (0, 16, 256):
        zones = [
            Zone(f"s{i}", SPEED_LIMIT, z.xs, z.ys, 0.3)
            for i, z in enumerate(big_polygon(box, 100, i / 1000) for i in range(count))
        ]
        for where, pose in (("outside", (50.0, 50.0)), ("inside", (10.0, 10.0))):
            safety = SafetyLayer(SafetyParams())
            safety.zones.set(zones)
            safety.scan(scan)
            safety.zones.pose("r1", 10.0, *pose)

            def verdicts(s: SafetyLayer = safety) -> None:
                for _ in range(100):
                    s.judge("r1", 1.0, FOOTPRINT_M, 10.0, 2.5)

            out[f"verdict, {count} speed zones, robot {where}, ms"] = round(
                best_ms(verdicts, repeat) / 100, 4
            )
            if count == 0:
                break
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pnav.bench.zone_cost")
    parser.add_argument("--world", default="warehouse", help="a shipped world or a world file")
    parser.add_argument("--repeat", type=int, default=5, help="passes per figure (best kept)")
    parser.add_argument("--json", help="write the figures as JSON here ('-': stdout)")
    args = parser.parse_args(argv)
    world = load_world(resolve_world(args.world))
    g = world.grid
    data = MapData(world.name, "bench", g.cells >= 50, g.resolution, g.origin)
    results = {"planner": planner_figures(data, args.repeat), "bridge": bridge_figures(args.repeat)}
    print(
        f"zones on {world.name} ({results['planner']['map_cells']} cells), best of {args.repeat}:"
    )
    for part, figures in results.items():
        for name, value in figures.items():
            if name != "map_cells":
                print(f"  {part:<8} {name:<58} {value}")
    emit({"benchmark": "zones", "machine": machine(), "results": results}, args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

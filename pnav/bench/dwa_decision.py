"""Benchmark: one dwa decision, with the default params and with the heaviest a strategy row
may ask for.

``python -m pnav.bench.dwa_decision [--scenes N] [--json FILE]`` decides ``N`` made-up scenes with
each set: ``default`` and ``worst`` (the params of issue 28) on the Jackal's 720-beam
270-degree lidar in clutter 0.5 to 6 m away, a path 10 m ahead, driving at 1 m/s; ``barn``
with the default params in BARN-like clutter (up to 160 posts and crates ray-cast into the
lidar, most hits within reach), a bending path of a point every 5 cm, at speeds from a
standstill to the top; ``barn_box`` the same scenes with the Jackal's true box, so the
winner is put to the safety layer's test too (pnav_local/veto.py). Per set it prints the
milliseconds per decision (the mean of the best pass, and the median and 99th percentile of
every decision, wall and CPU), the trajectories and poses rolled out, the peak memory of one
decision (tracemalloc: numpy reports its arrays to it) and a digest of every command
decided, so two trees can be compared for speed *and* for giving the same decisions.
"""

from __future__ import annotations

import argparse
import hashlib
import math
import time
import tracemalloc
from collections.abc import Mapping
from typing import Any

import numpy as np

from common.contract.planned_path import PlannedPath
from common.contract.records import LaserScan, Odometry, Robot
from pnav.bench.figures import decision_options, emit, machine
from pnav_local.dwa import choose, command_for
from pnav_local.dwa_params import DwaParams

JACKAL = Robot("r1", 2.0, 4.0, 0.22, 270.0, max_linear_accel_mps2=10.0, max_angular_accel_rps2=20.0)
BEAMS = 720
FOV = math.radians(270.0)
PATH = PlannedPath(1, "r1", 0.0, 1, "goal", 10.0, 0.0, (0.0, 10.0), (0.0, 0.0), 10.0)

# the params of the stalled controller: each within its documented range
WORST: dict[str, Any] = {
    "dwa_steps": 50,
    "dwa_linear_samples": 50,
    "dwa_angular_samples": 100,
    "dwa_horizon_s": 10,
}
PARAMS: dict[str, Mapping[str, Any]] = {
    "default": {},
    "worst": WORST,
    "barn": {},
    "barn_box": {},
}
# the Jackal's true outline (robot frame, m, counter-clockwise): ``barn_box`` decides the
# barn scenes with it, the safety layer's test put to each winner (pnav_local/veto.py)
BOX = ((-0.254, -0.215), (0.254, -0.215), (0.254, 0.215), (-0.254, 0.215))
POLYGONS: dict[str, Any] = {"barn_box": BOX}
Scene = tuple[LaserScan, Odometry, PlannedPath]


def scenes(n: int, seed: int) -> list[Scene]:
    """``n`` cluttered scans with the odometry read with them (and the straight path)."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        ranges = rng.uniform(3.0, 12.0, BEAMS)
        for _ in range(rng.integers(4, 12)):  # posts and crates, a few to 40 beams wide
            at, width = int(rng.integers(0, BEAMS)), int(rng.integers(3, 40))
            ranges[np.arange(at, at + width) % BEAMS] = rng.uniform(0.5, 6.0)
        ranges[ranges > 10.0] = np.inf
        scan = LaserScan(
            i + 1, "r1", 0.1 * i, -FOV / 2, FOV / (BEAMS - 1), 0.1, 10.0, ranges.astype("f4")
        )
        odom = Odometry(i + 1, "r1", 0.1 * i, 0.0, 0.0, float(rng.uniform(-0.2, 0.2)), 1.0, 0.0)
        out.append((scan, odom, PATH))
    return out


def barn(n: int, seed: int) -> list[Scene]:
    """``n`` BARN-like scenes: discs 0.15 to 0.5 m across within 4 m, as the lidar sees them."""
    rng = np.random.default_rng(seed)
    angles = -FOV / 2 + FOV / (BEAMS - 1) * np.arange(BEAMS)
    beams = np.column_stack([np.cos(angles), np.sin(angles)])
    out = []
    for i in range(n):
        k = int(rng.integers(60, 160))
        centres, radii = rng.uniform(-4.0, 4.0, (k, 2)), rng.uniform(0.075, 0.25, k)
        keep = np.hypot(*centres.T) - radii > 0.45
        centres, radii = centres[keep], radii[keep]
        along = beams @ centres.T
        disc = along**2 - ((centres**2).sum(axis=1) - radii**2)[None, :]
        t = np.where(disc >= 0.0, along - np.sqrt(np.maximum(disc, 0.0)), np.inf)
        ranges = np.where(t > 0.0, t, np.inf).min(axis=1, initial=np.inf)
        ranges = ranges + rng.normal(0.0, 0.005, BEAMS)
        ranges[ranges > 10.0] = np.inf
        scan = LaserScan(
            i + 1, "r1", 0.1 * i, -FOV / 2, FOV / (BEAMS - 1), 0.1, 10.0, ranges.astype("f4")
        )
        v, w = float(rng.choice([0.0, 0.05, 0.3, 1.0, 2.0])), float(rng.uniform(-1.0, 1.0))
        odom = Odometry(i + 1, "r1", 0.1 * i, 0.0, 0.0, float(rng.uniform(-0.5, 0.5)), v, w)
        bend = float(rng.uniform(-3.0, 3.0))
        xs = np.arange(0.0, 8.0, 0.05)
        ys = bend * np.sin(xs / 8.0 * math.pi / 2)
        path = PlannedPath(1, "r1", 0.0, 1, "goal", 8.0, float(ys[-1]), tuple(xs.tolist()),
                           tuple(ys.tolist()), 9.0)  # fmt: skip
        out.append((scan, odom, path))
    return out


def run(name: str, raw: Mapping[str, Any], n: int, seed: int, repeat: int) -> dict[str, Any]:
    data = barn(n, seed) if name.startswith("barn") else scenes(n, seed)
    params = DwaParams.read(raw)
    polygon = POLYGONS.get(name)
    digest = hashlib.sha256()
    best = best_cpu = math.inf
    trajectories = poses = 0
    walls: list[float] = []
    cpus: list[float] = []
    for attempt in range(repeat):
        started, cpu = time.perf_counter(), time.process_time()
        choices = []
        for s, o, path in data:
            one, one_cpu = time.perf_counter(), time.process_time()
            choices.append(choose(s, o, JACKAL, path, params, polygon))
            walls.append(time.perf_counter() - one)
            cpus.append(time.process_time() - one_cpu)
        best = min(best, time.perf_counter() - started)
        best_cpu = min(best_cpu, time.process_time() - cpu)
        if attempt == 0:
            for choice, (_, _, path) in zip(choices, data, strict=True):
                assert choice is not None
                trajectories = max(trajectories, len(choice.window.v))
                cmd = command_for(choice, path)
                digest.update(repr((cmd.linear, cmd.angular, cmd.reason)).encode())
    poses = trajectories * params.steps
    tracemalloc.start()
    choose(data[0][0], data[0][1], JACKAL, data[0][2], params, polygon)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return {
        "params": name,
        "asked": dict(raw),
        "steps": params.steps,
        "samples": [params.linear_samples, params.angular_samples],
        "trajectories": trajectories,
        "poses": poses,
        "ms_per_decision": round(best / n * 1e3, 2),
        # the process's CPU time (every thread's: numpy's BLAS may use more than one):
        # steadier than the wall on a shared machine
        "cpu_ms_per_decision": round(best_cpu / n * 1e3, 2),
        # every decision of every pass: the median, and the tail a controller tick meets
        "median_ms": round(float(np.median(walls)) * 1e3, 2),
        "p99_ms": round(float(np.percentile(walls, 99)) * 1e3, 2),
        "cpu_median_ms": round(float(np.median(cpus)) * 1e3, 2),
        "cpu_p99_ms": round(float(np.percentile(cpus, 99)) * 1e3, 2),
        "peak_mb": round(peak / 2**20, 1),
        "digest": digest.hexdigest()[:16],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pnav.bench.dwa_decision")
    decision_options(parser, "scenes", 50, repeat=3)
    parser.add_argument("--only", choices=sorted(PARAMS), help="one params set")
    parser.add_argument("--json", metavar="FILE", help="write the figures as JSON ('-': stdout)")
    args = parser.parse_args(argv)
    results = []
    for name, raw in PARAMS.items():
        if args.only and name != args.only:
            continue
        r = run(name, raw, args.scenes, args.seed, args.repeat)
        results.append(r)
        print(
            f"{name:<8} {r['ms_per_decision']:8.2f} ms per decision "
            f"({r['cpu_ms_per_decision']:.2f} ms CPU; median {r['median_ms']:.2f}, p99 "
            f"{r['p99_ms']:.2f}; CPU median {r['cpu_median_ms']:.2f}, p99 "
            f"{r['cpu_p99_ms']:.2f}), {r['trajectories']} "
            f"trajectories x {r['steps']} steps = {r['poses']} poses, peak {r['peak_mb']} MB, "
            f"digest {r['digest']}"
        )
    emit({"benchmark": "dwa decision", "machine": machine(), "results": results}, args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

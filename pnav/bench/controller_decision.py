"""Benchmark: the controller's own decisions per scan, without I/O.

``python -m pnav.bench.controller_decision [--scans N] [--seed S]`` runs the shipped reactive
scenarios' ``decide`` (safety_stop, avoid_left, avoid_right: what GOTO_AVOID runs on every
fresh scan) on N scans made up of walls, near obstacles in random sectors and empty beams,
each scan a new object as the store hands them over, and prints the microseconds per scan and
a digest of every command decided, so two trees can be compared for speed *and* for giving
the same decisions (the digest must not change).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import time
from typing import Any

import numpy as np

from common.contract.records import LaserScan, Odometry, Robot
from pnav.bench.figures import decision_options
from services.controller.avoid_left import AvoidLeft
from services.controller.avoid_right import AvoidRight
from services.controller.safety_stop import SafetyStop

SCENARIOS = (SafetyStop, AvoidLeft, AvoidRight)
BEAMS = 360
ROBOT = Robot("r1", 0.22, 2.84, 0.105, 20.0)


def scans(n: int, seed: int) -> list[tuple[LaserScan, Odometry]]:
    """``n`` scans (360 beams, 3.5 m range) with odometry, from ``seed``."""
    rng = np.random.default_rng(seed)
    out: list[tuple[LaserScan, Odometry]] = []
    for i in range(n):
        ranges = rng.uniform(0.8, 4.5, BEAMS)
        for _ in range(rng.integers(0, 4)):  # near obstacles, a few beams wide
            at, width = int(rng.integers(0, BEAMS)), int(rng.integers(3, 40))
            ranges[np.arange(at, at + width) % BEAMS] = rng.uniform(0.12, 0.7)
        ranges[ranges > 3.5] = np.inf
        scan = LaserScan(
            i + 1, "r1", 0.05 * i, -math.pi, 2 * math.pi / BEAMS, 0.12, 3.5, ranges.astype("f4")
        )
        speed = float(rng.choice([0.0, 0.1, 0.22, -0.1]))
        odom = Odometry(i + 1, "r1", 0.05 * i, 0.0, 0.0, 0.0, speed, 0.0)
        out.append((scan, odom))
    return out


def run(n: int, seed: int, repeat: int) -> dict[str, Any]:
    data = scans(n, seed)
    params: dict[str, Any] = {}
    digest = hashlib.sha256()
    best = math.inf
    for attempt in range(repeat):
        fresh = [(LaserScan(**vars(s)), o) for s, o in data]  # new objects each time
        started = time.perf_counter()
        decided = [[c.decide(s, o, ROBOT, params) for c in SCENARIOS] for s, o in fresh]
        best = min(best, time.perf_counter() - started)
        if attempt == 0:
            for row in decided:
                digest.update(repr(row).encode())
    commands = sum(1 for s, o in data for c in SCENARIOS if c.decide(s, o, ROBOT, params))
    return {
        "benchmark": "controller decisions",
        "scans": n,
        "scenarios": [c.scenario for c in SCENARIOS],
        "us_per_scan": round(best / n * 1e6, 1),
        "commands": commands,
        "digest": digest.hexdigest()[:16],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pnav.bench.controller_decision")
    decision_options(parser, "scans", 5000, repeat=5)
    args = parser.parse_args(argv)
    result = run(args.scans, args.seed, args.repeat)
    print(
        f"{result['us_per_scan']} us per scan ({', '.join(result['scenarios'])}), "
        f"{result['commands']} commands, digest {result['digest']}"
    )
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

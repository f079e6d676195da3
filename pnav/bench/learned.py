"""Benchmark: one learned_drive decision against one dwa decision, on the same scenes.

``python -m pnav.bench.learned [--model FILE] [--scenes N] [--set NAME] [--db-dir DIR...]
[--json FILE]`` decides the made-up scenes of ``pnav.bench.dwa_decision`` (``default``: the
Jackal in clutter, a path 10 m ahead; ``barn``: BARN-like clutter and a bending path;
``barn_box``: those with the Jackal's true box) with dwa's default params and with
learned_drive, and prints the milliseconds per decision of each (best of the passes, wall
and CPU) and their ratio. ``--db-dir`` decides instead the states of kept runs (``pnav bench
nav --keep-db``): each recorded decision's scan, odometry, path and robot row (its
footprint), as the controller met them.

learned_drive's cost is the features, the model and its check (pnav_learned.candidates: the
proposal, and if it fails its neighbours on dwa's lattice, rolled out against the scan with
the footprint; for a classifier over dwa's lattice, its likeliest cells as one batch, and
dwa's own decision when none passes), so it depends on the scenes: the share of decisions
whose proposal passed at once (or, for a lattice classifier, that fell back to dwa) and the
candidates checked a decision are printed too. Without ``--model`` the model is
a (32, 32) network with random weights: its cost is the cost of any model of that shape.
"""

from __future__ import annotations

import argparse
import itertools
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from pnav.bench import recorded
from pnav.bench.dwa_decision import JACKAL, POLYGONS, barn, scenes
from pnav.bench.figures import decision_options, emit, machine
from pnav_learned.drive import recommend
from pnav_learned.features import FEATURES
from pnav_learned.model import DRIVE_KINDS, FORMAT, Model, load, parse
from pnav_local.dwa import choose
from pnav_local.dwa_params import DwaParams


def random_model(hidden: tuple[int, ...] = (32, 32)) -> Model:
    rng = np.random.default_rng(0)
    n, widths = len(FEATURES), (len(FEATURES), *hidden, 2)
    layers = [
        {"w": rng.normal(size=(a, b)).tolist(), "b": [0.0] * b}
        for a, b in itertools.pairwise(widths)
    ]
    doc = {
        "format": FORMAT,
        "name": "random",
        "version": "random",
        "features": list(FEATURES),
        "targets": ["linear_mps", "angular_rps"],
        **{k: [0.0] * n for k in ("x_mean", "x_min")},
        "x_scale": [1.0] * n,
        "x_max": [1.0] * n,
        "y_mean": [0.0, 0.0],
        "y_scale": [1.0, 1.0],
        "layers": layers,
    }
    return parse(doc, "random")


def timed(decide: Callable[..., object], data: list[Any], repeat: int) -> tuple[float, float]:
    best = best_cpu = math.inf
    for _ in range(repeat):
        started, cpu = time.perf_counter(), time.process_time()
        for scene in data:
            decide(*scene)
        best = min(best, time.perf_counter() - started)
        best_cpu = min(best_cpu, time.process_time() - cpu)
    return best / len(data) * 1e3, best_cpu / len(data) * 1e3


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pnav.bench.learned")
    parser.add_argument("--model", help="a model file (default: random weights, 32x32)")
    decision_options(parser, "scenes", 200, repeat=3)
    parser.add_argument(
        "--set", default="default", choices=("default", "barn", "barn_box"), help="the scenes"
    )
    parser.add_argument(
        "--db-dir",
        type=Path,
        nargs="+",
        metavar="DIR",
        help="kept runs' databases: decide their recorded states instead of --set's scenes",
    )
    parser.add_argument("--json", metavar="FILE", help="write the figures as JSON ('-': stdout)")
    args = parser.parse_args(argv)
    model = load(args.model, kind=DRIVE_KINDS) if args.model else random_model()
    params = DwaParams.read({})
    if args.db_dir:
        data = [
            (scan, odom, path, robot, robot.footprint_polygon)
            for scan, odom, path, robot in recorded.states(args.db_dir)
        ]
        scene_set = "recorded"
    else:
        polygon = POLYGONS.get(args.set)
        scenes_of = barn if args.set.startswith("barn") else scenes
        data = [(s, o, p, JACKAL, polygon) for s, o, p in scenes_of(args.scenes, args.seed)]
        scene_set = args.set
    dwa_ms, dwa_cpu = timed(lambda s, o, p, r, f: choose(s, o, r, p, params, f), data, args.repeat)
    ml_ms, ml_cpu = timed(
        lambda s, o, p, r, f: recommend(model, s, o, r, p, None, params, f), data, args.repeat
    )
    said = [(recommend(model, s, o, r, p, None, params, f).inputs or {}) for s, o, p, r, f in data]
    checks = [int(inputs["checked"]) for inputs in said]
    # a lattice classifier's top cells are one batch; what counts is how often dwa decides
    fallbacks = sum(1 for inputs in said if inputs.get("fallback")) / max(1, len(said))
    first = sum(1 for c in checks if c == 1) / max(1, len(checks))
    checked = sum(checks) / max(1, len(checks))
    results = {
        "model": model.path,
        "set": scene_set,
        "decisions": len(data),
        "lattice": model.lattice,
        "proposal_passed_share": None if model.lattice else round(first, 4),
        "fallback_share": round(fallbacks, 4) if model.lattice else None,
        "candidates_checked_mean": round(checked, 2),
        "dwa_ms_per_decision": round(dwa_ms, 3),
        "dwa_cpu_ms_per_decision": round(dwa_cpu, 3),
        "learned_ms_per_decision": round(ml_ms, 3),
        "learned_cpu_ms_per_decision": round(ml_cpu, 3),
        "learned_share_of_dwa": round(ml_ms / dwa_ms, 4),
        "learned_cpu_share_of_dwa": round(ml_cpu / dwa_cpu, 4),
    }
    print(
        f"dwa           {dwa_ms:8.3f} ms per decision ({dwa_cpu:.3f} ms CPU)\n"
        f"learned_drive {ml_ms:8.3f} ms per decision ({ml_cpu:.3f} ms CPU),"
        f" {100 * ml_ms / dwa_ms:.1f} % of dwa's ({100 * ml_cpu / dwa_cpu:.1f} % CPU)\n"
        + (
            f"{len(data)} decisions; dwa decided (no likely cell admissible) in"
            f" {100 * fallbacks:.1f} %, {checked:.2f} cells checked a decision on average"
            if model.lattice
            else f"{len(data)} decisions; the proposal passed at once in {100 * first:.1f} %,"
            f" {checked:.2f} candidates checked a decision on average"
        )
    )
    emit({"benchmark": "learned_drive decision", "machine": machine(), **results}, args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

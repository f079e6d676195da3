"""Benchmark: one learned_drive decision against one dwa decision, on the same scenes.

``python -m pnav.bench.learned [--model FILE] [--scenes N] [--set NAME] [--json FILE]`` decides
the made-up scenes of ``pnav.bench.dwa_decision`` (``default``: the Jackal in clutter, a path
10 m ahead; ``barn``: BARN-like clutter and a bending path; ``barn_box``: those with the
Jackal's true box, which dwa then checks too) with dwa's default params and with learned_drive
(features, then the model: it never looks at the footprint, so its cost is one for every set),
and prints the milliseconds per
decision of each (best of the passes, wall and CPU) and their ratio. Without ``--model`` the
model is a (32, 32) network with random weights: its cost is the cost of any model of that
shape, which is all a timing needs.
"""

from __future__ import annotations

import argparse
import itertools
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from pnav.bench.dwa_decision import JACKAL, POLYGONS, barn, scenes
from pnav.bench.figures import emit, machine
from pnav_learned.drive import recommend
from pnav_learned.features import FEATURES
from pnav_learned.model import FORMAT, Model, load, parse
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


def timed(
    decide: Callable[[Any, Any, Any], object], data: list[Any], repeat: int
) -> tuple[float, float]:
    best = best_cpu = math.inf
    for _ in range(repeat):
        started, cpu = time.perf_counter(), time.process_time()
        for scan, odom, path in data:
            decide(scan, odom, path)
        best = min(best, time.perf_counter() - started)
        best_cpu = min(best_cpu, time.process_time() - cpu)
    return best / len(data) * 1e3, best_cpu / len(data) * 1e3


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pnav.bench.learned")
    parser.add_argument("--model", help="a model file (default: random weights, 32x32)")
    parser.add_argument("--scenes", type=int, default=200)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument(
        "--set", default="default", choices=("default", "barn", "barn_box"), help="the scenes"
    )
    parser.add_argument("--repeat", type=int, default=3, help="best of this many passes")
    parser.add_argument("--json", metavar="FILE", help="write the figures as JSON ('-': stdout)")
    args = parser.parse_args(argv)
    model = load(args.model) if args.model else random_model()
    data = (barn if args.set.startswith("barn") else scenes)(args.scenes, args.seed)
    params = DwaParams.read({})
    polygon = POLYGONS.get(args.set)
    dwa_ms, dwa_cpu = timed(
        lambda s, o, p: choose(s, o, JACKAL, p, params, polygon), data, args.repeat
    )
    ml_ms, ml_cpu = timed(
        lambda s, o, p: recommend(model, s, o, JACKAL, p, None, params, polygon), data, args.repeat
    )
    results = {
        "model": model.path,
        "set": args.set,
        "dwa_ms_per_decision": round(dwa_ms, 3),
        "dwa_cpu_ms_per_decision": round(dwa_cpu, 3),
        "learned_ms_per_decision": round(ml_ms, 3),
        "learned_cpu_ms_per_decision": round(ml_cpu, 3),
        "learned_share_of_dwa": round(ml_ms / dwa_ms, 4),
    }
    print(
        f"dwa           {dwa_ms:8.3f} ms per decision ({dwa_cpu:.3f} ms CPU)\n"
        f"learned_drive {ml_ms:8.3f} ms per decision ({ml_cpu:.3f} ms CPU),"
        f" {100 * ml_ms / dwa_ms:.1f} % of dwa's"
    )
    emit({"benchmark": "learned_drive decision", "machine": machine(), **results}, args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

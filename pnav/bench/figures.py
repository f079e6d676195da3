"""Shared pieces of every benchmark: percentiles, the machine, printing, JSON output, the
options of a decision benchmark."""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np


def percentiles(
    samples: Sequence[float], points: Sequence[float] = (50, 95, 99)
) -> dict[str, float]:
    """``{"p50": ..., "p99": ..., "max": ..., "mean": ...}`` of ``samples``."""
    if not samples:
        return {}
    values = np.asarray(samples, dtype=float)
    out = {f"p{int(p)}": float(np.percentile(values, p)) for p in points}
    out["max"] = float(values.max())
    out["mean"] = float(values.mean())
    return out


def machine() -> dict[str, Any]:
    """What the figures were measured on."""
    import psutil

    return {
        "cpus": os.cpu_count(),
        "memory_gib": round(psutil.virtual_memory().total / 2**30, 1),
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
    }


def emit(result: dict[str, Any], json_path: str | None) -> None:
    """Write ``result`` as JSON to ``json_path`` ('-' for stdout)."""
    if not json_path:
        return
    text = json.dumps(result, indent=2, sort_keys=True)
    if json_path == "-":
        print(text)
    else:
        Path(json_path).write_text(text + "\n")
        print(f"wrote {json_path}")


def decision_options(
    parser: argparse.ArgumentParser, inputs: str, default_inputs: int, repeat: int
) -> None:
    """The options of a benchmark timing decisions on made-up inputs: how many
    (``--<inputs>``), the seed they are drawn with, and how many passes are timed (the
    best kept)."""
    parser.add_argument(f"--{inputs}", type=int, default=default_inputs)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--repeat", type=int, default=repeat, help="best of this many passes")

"""A synthetic dataset with a known rule, shaped as ``pnav learn dataset`` writes one."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pnav_learned.features import FEATURES, RANGE_CAP_M, SECTORS


def rule(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The policy that made the data: slow down near what is ahead, turn toward the carrot."""
    ahead = x[:, SECTORS // 2 - 1 : SECTORS // 2 + 1].min(axis=1)  # the two sectors ahead
    carrot = np.arctan2(x[:, FEATURES.index("carrot_y")], x[:, FEATURES.index("carrot_x")])
    linear = 0.2 * np.clip(ahead - 0.3, 0.0, 1.0)
    angular = 1.5 * np.clip(carrot, -1.0, 1.0)
    return linear, angular


def features(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    sectors = rng.uniform(0.2, RANGE_CAP_M, size=(n, SECTORS))
    speed = rng.uniform([0.0, -1.0], [0.22, 1.0], size=(n, 2))
    bearing = rng.uniform(-math.pi, math.pi, n)
    carrot = np.column_stack([0.6 * np.cos(bearing), 0.6 * np.sin(bearing)])
    target = np.column_stack([rng.uniform(0.5, 8.0, n), rng.uniform(-math.pi, math.pi, n)])
    return np.column_stack([sectors, speed, carrot, target])


def write(path: Path, n: int = 3000, seed: int = 1, shuffle: bool = False) -> None:
    x = features(n, seed)
    linear, angular = rule(x)
    if shuffle:  # the same targets, cut loose from the features: nothing to learn
        order = np.random.default_rng(seed + 1).permutation(n)
        linear, angular = linear[order], angular[order]
    columns = {name: x[:, i] for i, name in enumerate(FEATURES)}
    columns |= {"linear_mps_cmd": linear, "angular_rps_cmd": angular, "source": ["dwa"] * n}
    pq.write_table(pa.table(columns), path)

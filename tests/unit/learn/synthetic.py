"""A synthetic dataset with a known rule, shaped as ``pnav learn dataset`` writes one."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pnav_learned.features import FEATURES, RANGE_CAP_M, SECTORS
from pnav_learned.history import FORESIGHT_FEATURES
from pnav_learned.lattice import ANGULAR, CELLS, LINEAR


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


def foresight_rule(x: np.ndarray) -> np.ndarray:
    """What made the foresight data: no progress ahead when the robot moved little in the
    last second, the less so the nearer something was ahead in the last seconds."""
    moved = x[:, FORESIGHT_FEATURES.index("moved_1s")]
    ahead = x[:, FORESIGHT_FEATURES.index("ahead_min_3s")]
    return np.asarray(moved + 0.1 * ahead < 0.2)


def foresight_features(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = features(n, seed)
    base[:, FEATURES.index("target_dist")] = rng.uniform(1.0, 8.0, n)
    history = np.column_stack(
        [
            rng.uniform(1.0, 3.0, n),  # history_s
            rng.uniform(0.0, 0.3, n),  # moved_1s
            rng.uniform(0.0, 0.8, n),  # moved_3s
            rng.uniform(-0.3, 0.8, n),  # progress_3s
            rng.uniform(0.0, 3.0, n),  # turned_3s
            rng.uniform(0.0, 0.25, n),  # speed_mean_3s
            rng.uniform(0.2, 3.5, n),  # ahead_min_3s
        ]
    )
    return np.column_stack([base, history])


def write_foresight(path: Path, n: int = 4000, seed: int = 1, shuffle: bool = False) -> None:
    """A dataset as ``pnav learn dataset`` writes one, with progress_m made by the rule."""
    x = foresight_features(n, seed)
    stuck = foresight_rule(x)
    if shuffle:  # the same labels, cut loose from the features
        stuck = stuck[np.random.default_rng(seed + 1).permutation(n)]
    columns = {name: x[:, i] for i, name in enumerate(FORESIGHT_FEATURES)}
    columns["progress_m"] = np.where(stuck, 0.05, 0.9)
    pq.write_table(pa.table(columns), path)


def lattice_rule(x: np.ndarray) -> np.ndarray:
    """The cell of dwa's lattice the made-up policy picks (pnav_learned.lattice): slowest,
    middling or fastest by how free it is ahead, hard right, straight or hard left by where
    the carrot is."""
    ahead = x[:, SECTORS // 2 - 1 : SECTORS // 2 + 1].min(axis=1)
    carrot = np.arctan2(x[:, FEATURES.index("carrot_y")], x[:, FEATURES.index("carrot_x")])
    row = np.digitize(ahead, [1.2, 2.4]) * (LINEAR - 1) // 2
    column = np.digitize(carrot, [-0.5, 0.5]) * (ANGULAR - 1) // 2
    return row * ANGULAR + column


def write_lattice(path: Path, n: int = 4000, seed: int = 1, shuffle: bool = False) -> None:
    """Examples as ``pnav learn dataset --label dwa`` writes them, labelled with
    :func:`lattice_rule`'s cell; every cell admissible (so the label is the rule's)."""
    x = features(n, seed)
    cell = lattice_rule(x)
    if shuffle:
        cell = cell[np.random.default_rng(seed + 1).permutation(n)]
    columns = {name: x[:, i] for i, name in enumerate(FEATURES)}
    columns |= {
        "linear_mps_cmd": np.zeros(n),
        "angular_rps_cmd": np.zeros(n),
        "source": ["dwa"] * n,
        "dwa_cell": cell,
        "dwa_admissible": [[True] * len(CELLS)] * n,
    }
    pq.write_table(pa.table(columns), path)

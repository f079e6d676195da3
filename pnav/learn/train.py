"""``pnav learn train``: fit a small multilayer perceptron (scikit-learn, CPU) that maps a
decision's features to the velocity the stack commanded, and write it as a model file
learned_drive can run (pnav_learned.model: JSON, evaluated with numpy).

A fifth of the examples (a seeded draw) is held out; the file records the held-out R^2 and
mean absolute error of each target, the training data's SHA-256, the feature list and the
ranges the training data covered (learned_drive's confidence).
"""

from __future__ import annotations

import datetime
import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np

from common.errors import UsageError
from pnav.learn.dataset import matrix
from pnav_learned.features import FEATURES
from pnav_learned.model import FORMAT, TARGETS

DATA_TARGETS = ("linear_mps_cmd", "angular_rps_cmd")
HELD_OUT = 0.2
MIN_EXAMPLES = 20


def sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def read_examples(path: Path, sources: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
    except (OSError, ValueError) as exc:
        raise UsageError(f"--data {path}: not a Parquet file ({exc})") from None
    missing = [n for n in (*FEATURES, *DATA_TARGETS) if n not in table.column_names]
    if missing:
        raise UsageError(f"--data {path}: no column {', '.join(missing)} (pnav learn dataset)")
    columns = table.to_pydict()
    keep = np.ones(table.num_rows, dtype=bool)
    if sources:
        keep = np.isin(np.asarray(columns.get("source", [""] * table.num_rows)), sources)
    x, y = matrix(columns, FEATURES)[keep], matrix(columns, DATA_TARGETS)[keep]
    finite = np.all(np.isfinite(x), axis=1) & np.all(np.isfinite(y), axis=1)
    return x[finite], y[finite]


def fit(
    x: np.ndarray, y: np.ndarray, hidden: tuple[int, ...], seed: int
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The model document (without name and version) and its held-out metrics."""
    from sklearn.metrics import mean_absolute_error, r2_score
    from sklearn.neural_network import MLPRegressor

    if len(x) < MIN_EXAMPLES:
        raise UsageError(f"--data: {len(x)} usable examples, at least {MIN_EXAMPLES} needed")
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(x))
    cut = max(1, int(len(x) * HELD_OUT))
    test, train = order[:cut], order[cut:]
    x_mean, x_scale = x[train].mean(axis=0), x[train].std(axis=0)
    x_scale[x_scale < 1e-9] = 1.0  # a constant feature: leave it as it is
    y_mean, y_scale = y[train].mean(axis=0), y[train].std(axis=0)
    constant = y_scale < 1e-9  # e.g. dwa at top speed all along an easy run
    y_scale[constant] = 1.0
    net = MLPRegressor(
        hidden_layer_sizes=hidden,
        activation="relu",
        max_iter=600,
        early_stopping=True,
        random_state=seed,
    )
    net.fit((x[train] - x_mean) / x_scale, (y[train] - y_mean) / y_scale)
    # a target that never varied is its mean, exactly: the network's noise around it is not
    net.coefs_[-1][:, constant] = 0.0
    net.intercepts_[-1][constant] = 0.0
    predicted = net.predict((x[test] - x_mean) / x_scale) * y_scale + y_mean
    metrics: dict[str, Any] = {"train_examples": len(train), "held_out": len(test)}
    for i, name in enumerate(TARGETS):
        # R^2 of a target that barely varies in the held-out set says nothing (its MAE does)
        varies = float(np.var(y[test, i])) > 1e-8
        metrics[f"{name}_r2"] = float(r2_score(y[test, i], predicted[:, i])) if varies else None
        metrics[f"{name}_mae"] = float(mean_absolute_error(y[test, i], predicted[:, i]))
    doc: dict[str, Any] = {
        "format": FORMAT,
        "features": list(FEATURES),
        "targets": list(TARGETS),
        "x_mean": x_mean.tolist(),
        "x_scale": x_scale.tolist(),
        "x_min": x[train].min(axis=0).tolist(),
        "x_max": x[train].max(axis=0).tolist(),
        "y_mean": y_mean.tolist(),
        "y_scale": y_scale.tolist(),
        "layers": [
            {"w": w.tolist(), "b": b.tolist()}
            for w, b in zip(net.coefs_, net.intercepts_, strict=True)
        ],
        "metrics": metrics,
    }
    return doc, metrics


def train(
    data: Path,
    out: Path,
    *,
    name: str,
    hidden: tuple[int, ...] = (32, 32),
    sources: tuple[str, ...] = (),
    seed: int = 0,
) -> dict[str, Any]:
    """Train on ``data`` and write the model file ``out``; return its document."""
    if not data.is_file():
        raise UsageError(f"--data {data}: no such file")
    x, y = read_examples(data, sources)
    doc, _ = fit(x, y, hidden, seed)
    weights = json.dumps(doc["layers"], sort_keys=True).encode()
    doc = {
        "name": name,
        # the version names the weights: the same file trained again is the same version
        "version": hashlib.sha256(weights).hexdigest()[:12],
        **doc,
        "data_sha256": sha256(data),
        "sources": list(sources),
        "hidden": list(hidden),
        "trained_at": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }
    out.write_text(json.dumps(doc))
    return doc

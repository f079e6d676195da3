"""``pnav learn train``: fit a small multilayer perceptron (scikit-learn, CPU) and write it
as a model file a learned scenario can run (pnav_learned.model: JSON, evaluated with numpy).

Three targets (``--target``):

- ``drive`` (learned_drive): a regressor from a decision's features to the velocity the
  stack commanded; held-out R^2 and mean absolute error per target;
- ``lattice`` (learned_drive): a classifier from a decision's features to the cell of dwa's
  lattice dwa chose (pnav_learned.lattice; datasets made with ``--label dwa``, which have
  the ``dwa_cell`` and ``dwa_admissible`` columns); held out: how often dwa's cell, and an
  admissible cell, is among the k likeliest;
- ``foresight``: a classifier from a decision's features and the last seconds'
  (pnav_learned.history) to "no progress within 3 s" (the dataset's ``progress_m`` below
  ``NO_PROGRESS_M``); held-out precision and recall at foresight's threshold and others.

A fifth of the examples (a seeded draw) is held out, or the examples of other files
(``--test``: other worlds, the honest split); the file records the held-out metrics, the
training data's SHA-256, the feature list and the ranges the training data covered (the
scenarios' confidence).
"""

from __future__ import annotations

import datetime
import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np

from common.errors import UsageError
from pnav.learn.dataset import LATTICE, matrix
from pnav_learned.features import FEATURES
from pnav_learned.history import FORESIGHT_FEATURES, NEAR_TARGET_M, NO_PROGRESS_M, no_progress
from pnav_learned.lattice import ANGULAR, CELLS
from pnav_learned.model import FORMAT, TARGETS

DATA_TARGETS = ("linear_mps_cmd", "angular_rps_cmd")
HELD_OUT = 0.2
MIN_EXAMPLES = 20
TARGET_KINDS = ("drive", "foresight", "lattice")
# the lattice classifier's held-out metrics: how often dwa's cell, or an admissible one, is
# among the k likeliest (learned_drive checks TOP_K of them; fewer and more for comparison)
TOP_KS = (1, 2, 4, 6, 8)
FORESIGHT_THRESHOLDS = (0.4, 0.5, 0.6, 0.7)  # precision and recall reported at each
HORIZON_S = 3.0  # foresight's label: no progress within the next 3 s

Split = tuple[np.ndarray, np.ndarray]  # (train rows, held-out rows)


def sha256(paths: Path | list[Path]) -> str:
    """The data's SHA-256: the file's, or of several files in order, their bytes joined."""
    digest = hashlib.sha256()
    for path in [paths] if isinstance(paths, Path) else paths:
        with path.open("rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                digest.update(block)
    return digest.hexdigest()


def read_columns(
    paths: list[Path], needed: tuple[str, ...], horizon_s: float | None = None
) -> dict[str, list[Any]]:
    """The columns of every file, concatenated in order; ``horizon_s``: the outcome horizon
    the files must have been exported with (``pnav.horizon_s``, when they say)."""
    import pyarrow.parquet as pq

    out: dict[str, list[Any]] = {}
    for path in paths:
        try:
            table = pq.read_table(path)
        except (OSError, ValueError) as exc:
            raise UsageError(f"--data {path}: not a Parquet file ({exc})") from None
        missing = [n for n in needed if n not in table.column_names]
        if missing:
            raise UsageError(f"{path}: no column {', '.join(missing)} (pnav learn dataset)")
        said = (table.schema.metadata or {}).get(b"pnav.horizon_s")
        if horizon_s is not None and said is not None and float(said) != horizon_s:
            raise UsageError(
                f"{path}: outcomes over {float(said):g} s (pnav learn dataset --horizon);"
                f" this target's label is over {horizon_s:g} s"
            )
        columns = table.to_pydict()
        columns.setdefault("source", [""] * table.num_rows)
        for name, values in columns.items():
            out.setdefault(name, []).extend(values)
    return out


def read_examples(
    path: Path | list[Path], sources: tuple[str, ...]
) -> tuple[np.ndarray, np.ndarray]:
    """learned_drive's examples: features, and the commanded velocity."""
    columns = read_columns([path] if isinstance(path, Path) else path, (*FEATURES, *DATA_TARGETS))
    keep = np.ones(len(columns[FEATURES[0]]), dtype=bool)
    if sources:
        keep = np.isin(np.asarray(columns["source"]), sources)
    x, y = matrix(columns, FEATURES)[keep], matrix(columns, DATA_TARGETS)[keep]
    finite = np.all(np.isfinite(x), axis=1) & np.all(np.isfinite(y), axis=1)
    return x[finite], y[finite]


def read_lattice(paths: list[Path]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The lattice classifier's examples (``pnav learn dataset --label dwa``): features,
    dwa's cell, and which cells were admissible (for the held-out metrics). States where dwa
    had nothing to say, or every cell was refused, are left out."""
    columns = read_columns(paths, (*FEATURES, *LATTICE))
    x = matrix(columns, FEATURES)
    cell = np.asarray(columns["dwa_cell"], dtype=np.int64)
    keep = np.all(np.isfinite(x), axis=1) & (cell >= 0)
    ok = np.zeros((len(cell), len(CELLS)), dtype=bool)
    for i, row in enumerate(columns["dwa_admissible"]):
        if keep[i] and len(row) == len(CELLS):
            ok[i] = row
        else:
            keep[i] = False
    return x[keep], passing(cell[keep], ok[keep]), ok[keep]


def passing(cell: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Each example's label: dwa's cell where it passes learned_drive's check, else the
    admissible cell nearest it on the grid (dwa's choice may be off the grid: a turn rate
    facing the carrot, a two-segment arc, or admitted only by squeezing; its nearest cell
    may then fail where one beside it passes), or dwa's cell where none passes. The
    classifier learns cells that pass, so its likeliest are seldom all refused."""
    i, j = np.divmod(np.arange(len(CELLS)), ANGULAR)
    ci, cj = np.divmod(cell, ANGULAR)
    far = np.hypot(i[None, :] - ci[:, None], j[None, :] - cj[:, None])
    far = np.where(ok, far, np.inf)
    best = np.argmin(far, axis=1)
    return np.where(np.isfinite(far.min(axis=1)), best, cell)


def fit_lattice(
    x: np.ndarray,
    y: np.ndarray,
    ok: np.ndarray,
    hidden: tuple[int, ...],
    seed: int,
    held_out: int | None = None,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """learned_drive's classifier over dwa's lattice (pnav_learned.lattice): the model
    document and its held-out metrics: dwa's cell among the k likeliest, and an admissible
    cell among them (what decides whether learned_drive falls back to dwa)."""
    from sklearn.neural_network import MLPClassifier

    train, test = _split_enough(x, seed, held_out)
    x_mean, x_scale = _scaling(x[train])
    net = MLPClassifier(
        hidden_layer_sizes=hidden,
        activation="relu",
        alpha=1e-3,
        max_iter=300,
        early_stopping=True,
        n_iter_no_change=10,
        random_state=seed,
    )
    net.fit((x[train] - x_mean) / x_scale, y[train])
    # sklearn has an output per class seen (one logistic output for two): the file has one
    # per cell, a cell never seen in training never likely
    seen = np.asarray(net.classes_, dtype=np.int64)
    if len(seen) < 3:
        raise UsageError(f"--data: dwa chose {len(seen)} cells only: nothing to learn")
    last_w, last_b = net.coefs_[-1], net.intercepts_[-1]
    w = np.zeros((last_w.shape[0], len(CELLS)))
    b = np.full(len(CELLS), -30.0)
    w[:, seen], b[seen] = last_w, last_b
    net.coefs_[-1], net.intercepts_[-1] = w, b
    h = (x[test] - x_mean) / x_scale
    for i, (lw, lb) in enumerate(zip(net.coefs_, net.intercepts_, strict=True)):
        h = h @ lw + lb
        if i < len(net.coefs_) - 1:
            h = np.maximum(h, 0.0)
    order = np.argsort(-h, axis=1)
    metrics: dict[str, Any] = {
        "train_examples": len(train),
        "held_out": len(test),
        "cells_seen": len(seen),
    }
    rows = np.arange(len(test))[:, None]
    for k in TOP_KS:
        top = order[:, :k]
        metrics[f"dwa_cell_in_top{k}"] = float(np.mean(np.any(top == y[test][:, None], axis=1)))
        metrics[f"admissible_in_top{k}"] = float(np.mean(ok[test][rows, top].any(axis=1)))
    unscaled = (np.zeros(len(CELLS)), np.ones(len(CELLS)))
    doc = _document(
        net, FEATURES, CELLS, x[train], (x_mean, x_scale), unscaled, metrics, output="softmax"
    )
    return doc, metrics


def read_foresight(paths: list[Path]) -> tuple[np.ndarray, np.ndarray]:
    """foresight's examples: features of the decision and the last seconds, and whether the
    robot made no progress in the next 3 s. Examples whose run ended sooner (no outcome) or
    nearer the target than NEAR_TARGET_M (arriving, not stuck) are left out, as the
    scenario stays silent there."""
    columns = read_columns(paths, (*FORESIGHT_FEATURES, "progress_m"), HORIZON_S)
    x = matrix(columns, FORESIGHT_FEATURES)
    progress = np.asarray(columns["progress_m"], dtype=np.float64)
    keep = np.all(np.isfinite(x), axis=1) & np.isfinite(progress)
    keep &= x[:, FEATURES.index("target_dist")] >= NEAR_TARGET_M
    y = np.array([no_progress(p) for p in progress[keep]], dtype=np.float64)
    return x[keep], y


def split(n: int, seed: int, held_out: int | None = None) -> Split:
    """A seeded fifth held out, or (``held_out``: the last rows are another file's) those."""
    if held_out is not None:
        return np.arange(n - held_out), np.arange(n - held_out, n)
    order = np.random.default_rng(seed).permutation(n)
    cut = max(1, int(n * HELD_OUT))
    return order[cut:], order[:cut]


def _split_enough(x: np.ndarray, seed: int, held_out: int | None) -> Split:
    """:func:`split` of ``x``'s rows, refused (UsageError) below MIN_EXAMPLES."""
    if len(x) < MIN_EXAMPLES:
        raise UsageError(f"--data: {len(x)} usable examples, at least {MIN_EXAMPLES} needed")
    return split(len(x), seed, held_out)


def _scaling(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each feature's mean and spread over the training rows ``x`` (the network sees the
    features standardised); a constant feature keeps spread 1: it is left as it is."""
    x_mean, x_scale = x.mean(axis=0), x.std(axis=0)
    x_scale[x_scale < 1e-9] = 1.0
    return x_mean, x_scale


def _document(
    net: Any,
    features: tuple[str, ...],
    targets: tuple[str, ...],
    x_train: np.ndarray,
    x_scaling: tuple[np.ndarray, np.ndarray],
    y_scaling: tuple[np.ndarray, np.ndarray],
    metrics: dict[str, Any],
    output: str | None = None,
) -> dict[str, Any]:
    """The model document (pnav_learned.model's format, without name and version) of the
    fitted ``net``: the features' scaling and the ranges training covered, the targets'
    scaling, the layers and the held-out ``metrics``; ``output``: how the last layer is
    read, where not as it is ("logistic": a probability)."""
    doc: dict[str, Any] = {"format": FORMAT, "features": list(features), "targets": list(targets)}
    if output is not None:
        doc["output"] = output
    return doc | {
        "x_mean": x_scaling[0].tolist(),
        "x_scale": x_scaling[1].tolist(),
        "x_min": x_train.min(axis=0).tolist(),
        "x_max": x_train.max(axis=0).tolist(),
        "y_mean": y_scaling[0].tolist(),
        "y_scale": y_scaling[1].tolist(),
        "layers": [
            {"w": w.tolist(), "b": b.tolist()}
            for w, b in zip(net.coefs_, net.intercepts_, strict=True)
        ],
        "metrics": metrics,
    }


def fit(
    x: np.ndarray,
    y: np.ndarray,
    hidden: tuple[int, ...],
    seed: int,
    held_out: int | None = None,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The model document (without name and version) and its held-out metrics."""
    from sklearn.metrics import mean_absolute_error, r2_score
    from sklearn.neural_network import MLPRegressor

    train, test = _split_enough(x, seed, held_out)
    x_mean, x_scale = _scaling(x[train])
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
    doc = _document(net, FEATURES, TARGETS, x[train], (x_mean, x_scale), (y_mean, y_scale), metrics)
    return doc, metrics


def fit_foresight(
    x: np.ndarray,
    y: np.ndarray,
    hidden: tuple[int, ...],
    seed: int,
    held_out: int | None = None,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """foresight's classifier: the model document (without name and version) and its
    held-out metrics (precision and recall of "no progress within 3 s" at thresholds)."""
    from sklearn.neural_network import MLPClassifier

    train, test = _split_enough(x, seed, held_out)
    if len(np.unique(y[train])) < 2:
        raise UsageError("--data: every training example has the same label: nothing to learn")
    x_mean, x_scale = _scaling(x[train])
    # no early stopping (which stopped short of sharp probabilities on a synthetic rule:
    # recall 0.79 against 0.91 at 0.6), and a stronger L2 penalty against over-fitting
    net = MLPClassifier(
        hidden_layer_sizes=hidden,
        activation="relu",
        alpha=1e-2,
        max_iter=500,
        n_iter_no_change=20,
        random_state=seed,
    )
    net.fit((x[train] - x_mean) / x_scale, y[train].astype(int))
    p = net.predict_proba((x[test] - x_mean) / x_scale)[:, 1]
    truth = y[test] > 0.5
    metrics: dict[str, Any] = {
        "train_examples": len(train),
        "held_out": len(test),
        "held_out_positive": int(truth.sum()),
        "train_positive": int(y[train].sum()),
    }
    # onset: the held-out examples where the robot was still making progress (the last 3 s),
    # so that a "no progress" ahead is foresight's to see, not the present carried on
    onset = x[test, FORESIGHT_FEATURES.index("progress_3s")] >= NO_PROGRESS_M
    metrics["held_out_onset"] = int(onset.sum())
    metrics["held_out_onset_positive"] = int((onset & truth).sum())
    for threshold in FORESIGHT_THRESHOLDS:
        for prefix, within in (("", np.ones_like(truth)), ("onset_", onset)):
            said, real = (p >= threshold) & within, truth & within
            hits = int((said & real).sum())
            metrics[f"{prefix}precision_{threshold:.1f}"] = (
                hits / int(said.sum()) if said.any() else None
            )
            metrics[f"{prefix}recall_{threshold:.1f}"] = (
                hits / int(real.sum()) if real.any() else None
            )
    # a probability as it is: no target scaling
    unscaled = (np.zeros(1), np.ones(1))
    doc = _document(
        net,
        FORESIGHT_FEATURES,
        ("no_progress",),
        x[train],
        (x_mean, x_scale),
        unscaled,
        metrics,
        output="logistic",
    )
    return doc, metrics


def train(
    data: Path | list[Path],
    out: Path,
    *,
    name: str,
    hidden: tuple[int, ...] = (32, 32),
    sources: tuple[str, ...] = (),
    seed: int = 0,
    target: str = "drive",
    test: list[Path] | None = None,
) -> dict[str, Any]:
    """Train on ``data`` (a file, or several) and write the model file ``out``; return its
    document. ``test``: files whose examples are the held-out set (else a seeded fifth)."""
    files = [data] if isinstance(data, Path) else list(data)
    for path in [*files, *(test or [])]:
        if not path.is_file():
            raise UsageError(f"--data {path}: no such file")
    if target not in TARGET_KINDS:
        raise UsageError(f"--target {target!r}: one of {', '.join(TARGET_KINDS)}")

    def read(paths: list[Path]) -> tuple[np.ndarray, np.ndarray]:
        return read_foresight(paths) if target == "foresight" else read_examples(paths, sources)

    held: int | None = None
    if target == "lattice":
        x, y, ok = read_lattice(files)
        if test:
            tx, ty, tok = read_lattice(test)
            x, y, held = np.concatenate([x, tx]), np.concatenate([y, ty]), len(tx)
            ok = np.concatenate([ok, tok])
        doc, _ = fit_lattice(x, y, ok, hidden, seed, held)
    else:
        x, y = read(files)
        if test:
            tx, ty = read(test)
            x, y, held = np.concatenate([x, tx]), np.concatenate([y, ty]), len(tx)
        doc, _ = (fit_foresight if target == "foresight" else fit)(x, y, hidden, seed, held)
    weights = json.dumps(doc["layers"], sort_keys=True).encode()
    doc = {
        "name": name,
        # the version names the weights: the same file trained again is the same version
        "version": hashlib.sha256(weights).hexdigest()[:12],
        **doc,
        "data_sha256": sha256(files),
        "test_sha256": sha256(test) if test else None,
        "sources": list(sources),
        "hidden": list(hidden),
        "trained_at": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }
    out.write_text(json.dumps(doc))
    return doc

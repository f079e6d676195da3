"""A learned model as the scenarios run it: a small multilayer perceptron in a JSON file,
evaluated with numpy (``pnav learn train`` writes it; docs/LEARNING.md, *The model file*).

JSON and not a pickle: a strategy row, which people write, names the file, and loading a
pickle runs whatever code it holds; a JSON file can at worst be refused. Everything is
checked at load, and a refused file says why (:class:`ModelRefused`): it is missing,
unreadable, not a model of this format, made for other features than the scenario computes,
of another version than the strategy asks for, or larger than a decision's work may be.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pnav_learned.errors import ModelRefused
from pnav_learned.features import FEATURES
from pnav_learned.lattice import CELLS

FORMAT = "pnav-mlp/1"
TARGETS = ("linear_mps", "angular_rps")  # learned_drive's; foresight names its own
# what the last layer's output goes through: a regression (learned_drive's proposal), a
# probability (foresight: a classifier's logit) or a distribution over classes (learned_drive's
# lattice classifier: one probability per cell of dwa's lattice, pnav_learned.lattice)
OUTPUTS = ("identity", "logistic", "softmax")
# bounds on one decision's work and on what a file may make us read, whatever it says
MAX_FILE_BYTES = 4 * 1024 * 1024
MAX_LAYERS = 6
MAX_WIDTH = 256

FloatArray = np.ndarray[tuple[int, ...], np.dtype[np.float64]]


@dataclass(frozen=True)
class Model:
    name: str
    version: str
    path: str
    x_mean: FloatArray
    x_scale: FloatArray
    x_min: FloatArray
    x_max: FloatArray
    y_mean: FloatArray
    y_scale: FloatArray
    weights: tuple[FloatArray, ...]
    biases: tuple[FloatArray, ...]
    metrics: dict[str, Any]
    output: str = "identity"

    def outputs(self, x: FloatArray) -> tuple[FloatArray, float]:
        """The model's outputs for one feature vector (in the order of its targets), and the
        share of features within the range the training data covered: a model is only known
        to do what it was shown."""
        h = (x - self.x_mean) / self.x_scale
        last = len(self.weights) - 1
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            h = h @ w + b
            if i < last:
                h = np.maximum(h, 0.0)
        if self.output == "softmax":
            y = np.exp(h - h.max())
            y /= y.sum()
        else:
            y = h * self.y_scale + self.y_mean
        if self.output == "logistic":
            y = 1.0 / (1.0 + np.exp(-np.clip(y, -60.0, 60.0)))
        inside = float(np.mean((x >= self.x_min) & (x <= self.x_max)))
        return y, inside

    @property
    def lattice(self) -> bool:
        """Whether this is a classifier over dwa's lattice (else a proposal's regression)."""
        return self.output == "softmax"

    def predict(self, x: FloatArray) -> tuple[float, float, float]:
        """(linear, angular, confidence) for one feature vector: learned_drive's model."""
        y, inside = self.outputs(x)
        return float(y[0]), float(y[1]), inside


def _array(doc: dict[str, Any], key: str, shape: tuple[int, ...]) -> FloatArray:
    try:
        a = np.asarray(doc[key], dtype=np.float64)
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelRefused(f"{key}: missing or not numbers ({exc})") from None
    if a.shape != shape:
        raise ModelRefused(f"{key}: shape {a.shape}, expected {shape}")
    if not np.all(np.isfinite(a)):
        raise ModelRefused(f"{key}: not all finite")
    return a


def _layers(
    doc: dict[str, Any], inputs: int, outputs: int
) -> tuple[tuple[FloatArray, ...], tuple[FloatArray, ...]]:
    layers = doc.get("layers")
    if not isinstance(layers, list) or not 1 <= len(layers) <= MAX_LAYERS:
        raise ModelRefused(f"layers: a list of 1 to {MAX_LAYERS} layers expected")
    weights, biases, width = [], [], inputs
    for i, layer in enumerate(layers):
        if not isinstance(layer, dict) or not isinstance(layer.get("b"), list):
            raise ModelRefused(f"layers[{i}]: an object with w and b expected")
        out = len(layer["b"])
        if i == len(layers) - 1 and out != outputs:
            raise ModelRefused(f"layers[{i}]: {out} outputs, expected {outputs}")
        if not 1 <= out <= MAX_WIDTH:
            raise ModelRefused(f"layers[{i}]: width {out}, at most {MAX_WIDTH}")
        weights.append(_array(layer, "w", (width, out)))
        biases.append(_array(layer, "b", (out,)))
        width = out
    return tuple(weights), tuple(biases)


@dataclass(frozen=True)
class Kind:
    """What a scenario runs: the features it computes, the targets, the output."""

    scenario: str
    features: tuple[str, ...]
    targets: tuple[str, ...]
    output: str = "identity"


DRIVE = Kind("learned_drive", FEATURES, TARGETS)
# learned_drive's classifier over dwa's lattice: the same features, a probability per cell
DRIVE_LATTICE = Kind("learned_drive", FEATURES, CELLS, "softmax")
# what learned_drive runs: either, told apart by the file's targets
DRIVE_KINDS = (DRIVE_LATTICE, DRIVE)
Kinds = Kind | tuple[Kind, ...]


def scenario_of(kind: Kinds) -> str:
    """The scenario that runs models of ``kind`` (or of these kinds)."""
    return (kind[0] if isinstance(kind, tuple) else kind).scenario


def _pick(doc: dict[str, Any], kind: Kinds) -> Kind:
    """The kind among ``kind`` whose targets the file names (the first if none: its refusal
    then says what was expected)."""
    kinds = kind if isinstance(kind, tuple) else (kind,)
    targets = doc.get("targets")
    return next((k for k in kinds if targets == list(k.targets)), kinds[0])


def parse(doc: Any, path: str, version: str | None = None, kind: Kinds = DRIVE) -> Model:
    """The model in ``doc`` (a decoded model file), or :class:`ModelRefused`. ``kind``: the
    kind of model the scenario runs, or several it can (told apart by the targets)."""
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ModelRefused(f"not a {FORMAT} model file")
    kind = _pick(doc, kind)
    features, targets = kind.features, kind.targets
    if doc.get("features") != list(features):
        raise ModelRefused(
            f"made for other features ({len(doc.get('features') or [])} named) than"
            f" {kind.scenario} computes ({len(features)}: {', '.join(features[:3])}...)"
        )
    if doc.get("targets") != list(targets):
        said = doc.get("targets")
        said = said if not isinstance(said, list) or len(said) <= 4 else f"{len(said)} targets"
        expected = list(targets) if len(targets) <= 4 else f"{len(targets)} cells"
        raise ModelRefused(f"targets {said}, expected {expected}")
    if doc.get("output", "identity") != kind.output:
        raise ModelRefused(f"output {doc.get('output')!r}, {kind.scenario} needs {kind.output!r}")
    found = str(doc.get("version", ""))
    if version is not None and found != version:
        raise ModelRefused(f"version {found!r}, the strategy asks for {version!r}")
    n = len(features)
    x_scale = _array(doc, "x_scale", (n,))
    y_scale = _array(doc, "y_scale", (len(targets),))
    if np.any(x_scale <= 0) or np.any(y_scale <= 0):
        raise ModelRefused("x_scale, y_scale: must be positive")
    weights, biases = _layers(doc, n, len(targets))
    metrics = doc.get("metrics") if isinstance(doc.get("metrics"), dict) else {}
    return Model(
        name=str(doc.get("name", "")),
        version=found,
        path=path,
        x_mean=_array(doc, "x_mean", (n,)),
        x_scale=x_scale,
        x_min=_array(doc, "x_min", (n,)),
        x_max=_array(doc, "x_max", (n,)),
        y_mean=_array(doc, "y_mean", (len(targets),)),
        y_scale=y_scale,
        weights=weights,
        biases=biases,
        metrics=metrics or {},
        output=kind.output,
    )


def load(path: str | Path, version: str | None = None, kind: Kinds = DRIVE) -> Model:
    """Read and check the model file at ``path`` for ``kind``'s scenario; ``version``: the
    one required."""
    p = Path(path)
    try:
        size = p.stat().st_size
        if size > MAX_FILE_BYTES:
            raise ModelRefused(f"{p}: {size} bytes, at most {MAX_FILE_BYTES}")
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ModelRefused(f"{p}: cannot be read ({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise ModelRefused(f"{p}: not text") from None
    try:
        doc = json.loads(text, parse_constant=lambda c: math.nan)
    except ValueError as exc:
        raise ModelRefused(f"{p}: not JSON ({exc})") from None
    try:
        return parse(doc, str(p), version, kind)
    except ModelRefused as exc:
        raise ModelRefused(f"{p}: {exc}") from None

"""A model file that is missing, corrupt, made for other features or of another version is
refused at load with a reason, and learned_drive then stands down."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pnav_learned import drive
from pnav_learned.errors import ModelRefused
from pnav_learned.features import FEATURES
from pnav_learned.model import FORMAT, MAX_WIDTH, load


def model_doc(width: int = 4, version: str = "v1") -> dict[str, Any]:
    n = len(FEATURES)
    rng = np.random.default_rng(0)
    return {
        "format": FORMAT,
        "name": "tiny",
        "version": version,
        "features": list(FEATURES),
        "targets": ["linear_mps", "angular_rps"],
        "x_mean": [0.0] * n,
        "x_scale": [1.0] * n,
        "x_min": [-1.0] * n,
        "x_max": [1.0] * n,
        "y_mean": [0.0, 0.0],
        "y_scale": [1.0, 1.0],
        "layers": [
            {"w": rng.normal(size=(n, width)).tolist(), "b": [0.0] * width},
            {"w": rng.normal(size=(width, 2)).tolist(), "b": [0.1, -0.2]},
        ],
    }


def write(path: Path, doc: Any) -> Path:
    path.write_text(json.dumps(doc))
    return path


def test_a_good_file_loads_and_predicts(tmp_path: Path) -> None:
    model = load(write(tmp_path / "m.json", model_doc()), "v1")
    linear, angular, confidence = model.predict(np.zeros(len(FEATURES)))
    assert (linear, angular, confidence) == (pytest.approx(0.1), pytest.approx(-0.2), 1.0)
    x = np.zeros(len(FEATURES))
    x[:5] = 2.0  # five features outside what training covered
    assert model.predict(x)[2] == pytest.approx(1 - 5 / len(FEATURES))


@pytest.mark.parametrize(
    ("content", "reason"),
    [
        (None, "cannot be read"),
        ("{not json", "not JSON"),
        ('{"format": "pickle"}', "not a pnav-mlp/1 model file"),
        ({**model_doc(), "features": ["a", "b"]}, "made for other features"),
        (model_doc(version="v2"), "version 'v2', the strategy asks for 'v1'"),
        (model_doc(width=MAX_WIDTH + 1), f"at most {MAX_WIDTH}"),
        ({**model_doc(), "x_scale": [0.0] * len(FEATURES)}, "must be positive"),
        ({**model_doc(), "x_mean": [1.0]}, "x_mean: shape"),
    ],
)
def test_a_bad_file_is_refused_with_a_reason(tmp_path: Path, content: Any, reason: str) -> None:
    path = tmp_path / "m.json"
    if content is not None:
        path.write_text(content if isinstance(content, str) else json.dumps(content))
    with pytest.raises(ModelRefused, match=reason.replace("(", r"\(")):
        load(path, "v1")


def test_learned_drive_stands_down_with_the_reason(tmp_path: Path) -> None:
    missing = {"learned_model": str(tmp_path / "none.json")}
    assert str(drive.model_for(missing)).startswith("model refused: ")
    assert "name none" in str(drive.model_for({}))
    good = write(tmp_path / "m.json", model_doc())
    found = drive.model_for({"learned_model": str(good), "learned_model_version": "v1"})
    assert not isinstance(found, str) and found.version == "v1"
    wrong = drive.model_for({"learned_model": str(good), "learned_model_version": "v9"})
    assert isinstance(wrong, str) and "asks for 'v9'" in wrong

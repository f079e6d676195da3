"""`pnav learn train` learns the rule that made a synthetic dataset, and writes a model file
learned_drive loads; with the targets shuffled away from the features it learns nothing."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from pnav.learn.train import passing, train
from pnav_learned.features import FEATURES
from pnav_learned.lattice import CELLS
from pnav_learned.model import DRIVE_KINDS, load
from tests.unit.learn import synthetic

pytestmark = pytest.mark.timeout(300)


def r2(truth: np.ndarray, predicted: np.ndarray) -> float:
    return 1.0 - float(np.sum((truth - predicted) ** 2) / np.sum((truth - truth.mean()) ** 2))


def test_training_learns_the_rule_that_made_the_data(tmp_path: Path) -> None:
    data, out = tmp_path / "data.parquet", tmp_path / "model.json"
    synthetic.write(data)
    doc = train(data, out, name="synthetic")
    assert doc["features"] == list(FEATURES)
    assert doc["data_sha256"] == hashlib.sha256(data.read_bytes()).hexdigest()
    assert doc["metrics"]["held_out"] == 600 and doc["metrics"]["train_examples"] == 2400
    assert doc["metrics"]["linear_mps_r2"] > 0.9 and doc["metrics"]["angular_rps_r2"] > 0.9

    # the file as learned_drive reads it, on examples it never saw
    model = load(out, doc["version"])
    assert (model.name, model.version) == ("synthetic", doc["version"])
    fresh = synthetic.features(400, seed=7)
    linear, angular = synthetic.rule(fresh)
    got = np.array([model.predict(x)[:2] for x in fresh])
    assert r2(linear, got[:, 0]) > 0.9 and r2(angular, got[:, 1]) > 0.9
    assert np.mean(np.abs(got[:, 1] - angular)) < 0.15  # rad/s
    assert model.predict(fresh[0])[2] == 1.0  # in the training data's range
    assert json.loads(out.read_text())["version"] == doc["version"]


def test_targets_unrelated_to_the_features_are_not_learned(tmp_path: Path) -> None:
    data, out = tmp_path / "data.parquet", tmp_path / "model.json"
    synthetic.write(data, shuffle=True)
    doc = train(data, out, name="noise")
    assert doc["metrics"]["linear_mps_r2"] < 0.2 and doc["metrics"]["angular_rps_r2"] < 0.2


def test_sources_keep_only_the_decisions_of_those_scenarios(tmp_path: Path) -> None:
    data, out = tmp_path / "data.parquet", tmp_path / "model.json"
    synthetic.write(data, n=100)
    from common.errors import UsageError

    with pytest.raises(UsageError, match="0 usable examples"):
        train(data, out, name="none", sources=("avoid_left",))


def test_a_target_that_never_varies_is_predicted_exactly(tmp_path: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    data, out = tmp_path / "data.parquet", tmp_path / "model.json"
    synthetic.write(data, n=400)
    table = pq.read_table(data)
    table = table.set_column(
        table.column_names.index("linear_mps_cmd"), "linear_mps_cmd", pa.array([0.22] * 400)
    )
    pq.write_table(table, data)
    doc = train(data, out, name="top speed")
    assert doc["metrics"]["linear_mps_r2"] is None  # nothing to explain
    assert doc["metrics"]["linear_mps_mae"] < 1e-12
    model = load(out)
    assert model.predict(synthetic.features(1, seed=3)[0])[0] == pytest.approx(0.22, abs=1e-12)


def test_foresight_learns_the_rule_that_made_its_labels(tmp_path: Path) -> None:
    from pnav_learned.foresight import KIND

    data, out = tmp_path / "data.parquet", tmp_path / "foresight.json"
    synthetic.write_foresight(data)
    doc = train(data, out, name="foresight", target="foresight", hidden=(16,))
    m = doc["metrics"]
    assert m["held_out"] == 800 and 0.1 < m["held_out_positive"] / 800 < 0.3
    assert m["precision_0.6"] > 0.9 and m["recall_0.6"] > 0.85
    # the file as foresight reads it, on examples it never saw
    model = load(out, doc["version"], KIND)
    fresh = synthetic.foresight_features(500, seed=9)
    truth = synthetic.foresight_rule(fresh)
    p = np.array([model.outputs(x)[0][0] for x in fresh])
    assert np.mean((p >= 0.6) == truth) > 0.9


def test_foresight_learns_nothing_from_labels_unrelated_to_the_features(tmp_path: Path) -> None:
    data, out = tmp_path / "data.parquet", tmp_path / "foresight.json"
    synthetic.write_foresight(data, shuffle=True)
    m = train(data, out, name="noise", target="foresight", hidden=(16,))["metrics"]
    assert (m["recall_0.6"] or 0.0) < 0.3 or (m["precision_0.6"] or 0.0) < 0.5


def test_foresight_held_out_on_other_files(tmp_path: Path) -> None:
    one, two, out = tmp_path / "a.parquet", tmp_path / "b.parquet", tmp_path / "f.json"
    synthetic.write_foresight(one, n=1000, seed=1)
    synthetic.write_foresight(two, n=300, seed=2)
    doc = train([one], out, name="f", target="foresight", hidden=(16,), test=[two])
    assert doc["metrics"]["train_examples"] == 1000 and doc["metrics"]["held_out"] == 300
    assert doc["test_sha256"] == hashlib.sha256(two.read_bytes()).hexdigest()


def test_foresight_refuses_a_dataset_of_another_horizon(tmp_path: Path) -> None:
    import pyarrow.parquet as pq

    from common.errors import UsageError

    data, out = tmp_path / "data.parquet", tmp_path / "f.json"
    synthetic.write_foresight(data, n=200)
    table = pq.read_table(data)
    pq.write_table(table.replace_schema_metadata({"pnav.horizon_s": "5.0"}), data)
    with pytest.raises(UsageError, match="outcomes over 5 s"):
        train(data, out, name="f", target="foresight", hidden=(4,))


def test_the_lattice_classifier_learns_the_cell_the_rule_picks(tmp_path: Path) -> None:
    data, out = tmp_path / "data.parquet", tmp_path / "model.json"
    synthetic.write_lattice(data)
    doc = train(data, out, name="cells", target="lattice", hidden=(32,))
    assert doc["targets"] == list(CELLS) and doc["output"] == "softmax"
    assert doc["metrics"]["dwa_cell_in_top1"] > 0.85
    assert doc["metrics"]["dwa_cell_in_top2"] > 0.95
    # the file as learned_drive reads it, on examples it never saw
    model = load(out, doc["version"], DRIVE_KINDS)
    assert model.lattice
    fresh = synthetic.features(400, seed=7)
    truth = synthetic.lattice_rule(fresh)
    likeliest = np.array([int(np.argmax(model.outputs(x)[0])) for x in fresh])
    assert np.mean(likeliest == truth) > 0.85


def test_the_lattice_classifier_learns_nothing_from_cells_cut_loose(tmp_path: Path) -> None:
    data, out = tmp_path / "data.parquet", tmp_path / "model.json"
    synthetic.write_lattice(data, shuffle=True)
    doc = train(data, out, name="noise", target="lattice", hidden=(32,))
    assert doc["metrics"]["dwa_cell_in_top1"] < 0.35  # the commonest cell: 22 %


def test_a_refused_cell_is_relabelled_with_the_nearest_that_passes() -> None:
    ok = np.zeros((2, len(CELLS)), dtype=bool)
    at = CELLS.index("cell_4_8")
    ok[0, [CELLS.index("cell_4_10"), CELLS.index("cell_5_9"), CELLS.index("cell_0_0")]] = True
    assert passing(np.array([at, at]), ok).tolist() == [CELLS.index("cell_5_9"), at]

"""A model file that is missing, corrupt, made for other features or of another version is
refused at load with a reason, and learned_drive then stands down."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, cast

import numpy as np
import pytest

from common.contract.models import RegisteredModel, pick
from common.controller_core.scenario import Host
from pnav_learned import registry
from pnav_learned.errors import ModelRefused
from pnav_learned.features import FEATURES
from pnav_learned.model import DRIVE, FORMAT, MAX_WIDTH, Kind, load


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


class Register:
    """The part of the controller's host the learned scenarios use: the model table."""

    def __init__(self, *rows: RegisteredModel) -> None:
        self.rows = list(rows)

    async def registered_model(self, name: str, version: str | None) -> RegisteredModel | None:
        return pick(self.rows, name, version)


async def resolve(host: Register, params: dict[str, Any], prefix: str, kind: Kind) -> Any:
    return await registry.resolve(cast(Host, host), params, prefix, kind)


async def test_learned_drive_stands_down_with_the_reason(tmp_path: Path) -> None:
    host = Register()
    missing = {"learned_model": str(tmp_path / "none.json")}
    assert str(await resolve(host, missing, "learned", DRIVE)).startswith("model refused: ")
    assert "name none" in str(await resolve(host, {}, "learned", DRIVE))
    good = write(tmp_path / "m.json", model_doc())
    params = {"learned_model": str(good), "learned_model_version": "v1"}
    found = await resolve(host, params, "learned", DRIVE)
    assert not isinstance(found, str) and found.model.version == "v1" and not found.registered
    params["learned_model_version"] = "v9"
    wrong = await resolve(host, params, "learned", DRIVE)
    assert isinstance(wrong, str) and "asks for 'v9'" in wrong
    assert "no model" in wrong and "'v9' is registered" in wrong


async def test_a_registered_version_is_the_one_loaded(tmp_path: Path) -> None:
    one = write(tmp_path / "one.json", model_doc(version="v1"))
    two = write(tmp_path / "two.json", model_doc(version="v2"))
    host = Register(
        RegisteredModel("drive", "v1", str(one)), RegisteredModel("drive", "v2", str(two))
    )
    named = {"learned_model": "drive", "learned_model_version": "v1"}
    found = await resolve(host, named, "learned", DRIVE)
    assert not isinstance(found, str) and found.model.path == str(one) and found.registered
    assert found.label == "model tiny version v1 (registered)"
    newest = await resolve(host, {"learned_model": "drive"}, "learned", DRIVE)
    assert not isinstance(newest, str) and newest.model.version == "v2"
    # a row whose file is not what it claims: refused (the row is a claim, not a proof)
    host.rows.append(RegisteredModel("drive", "v3", str(two)))
    lying = await resolve(host, {"learned_model": "drive"}, "learned", DRIVE)
    assert isinstance(lying, str) and "version 'v2', the strategy asks for 'v3'" in lying


async def test_foresight_refuses_a_model_made_for_another_scenario(tmp_path: Path) -> None:
    from pnav_learned.foresight import KIND as FORESIGHT

    host = Register()
    drive_model = write(tmp_path / "drive.json", model_doc())
    for content, reason in [
        (None, "cannot be read"),
        ("{broken", "not JSON"),
        (model_doc(), "made for other features"),
    ]:
        path = tmp_path / "f.json"
        path.unlink(missing_ok=True)
        if content is not None:
            path.write_text(content if isinstance(content, str) else json.dumps(content))
        found = await resolve(host, {"foresight_model": str(path)}, "foresight", FORESIGHT)
        assert isinstance(found, str) and reason in found, found
    # learned_drive's model named in foresight's params is refused, not run
    found = await resolve(host, {"foresight_model": str(drive_model)}, "foresight", FORESIGHT)
    assert isinstance(found, str) and "than foresight computes" in found


def test_learned_drive_remembers_its_stop_per_robot(tmp_path: Path) -> None:
    """The one stop on an empty path is remembered by each robot's rule: a stop for one
    robot never silences, or repeats, another's."""
    from common.contract.planned_path import PlannedPath
    from common.contract.records import Odometry, Robot
    from common.controller_core.scenario import ScenarioSpec
    from pnav_learned.drive import LearnedDrive
    from pnav_learned.registry import Found
    from tests.unit.learn.test_foresight import LaserScan

    model = Found(load(write(tmp_path / "m.json", model_doc()), "v1"), registered=False)
    rules = {}
    for robot in ("r1", "r2"):
        spec = ScenarioSpec(Robot(robot, 0.22, 2.84, 0.1, 20.0), "GOTO_LEARNED", {})
        rules[robot] = LearnedDrive(cast(Host, None), (robot, "learned_drive"), spec)
        rules[robot].found = model
        rules[robot].live = True
    scan = LaserScan(1, "r1", 0.0, 0.0, 0.1, 0.1, 3.5, np.full(8, 3.0, dtype=np.float32))
    odom = Odometry(1, "r1", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    def empty(path_id: int, robot: str) -> PlannedPath:
        return PlannedPath(path_id, robot, 0.0, None, "none", None, None, (), (), 0.0)

    said = []
    for robot, path_id in (("r1", 5), ("r2", 6), ("r1", 5), ("r2", 6), ("r1", 7)):
        rule = rules[robot] = rules[robot].rule_generation()[0]  # type: ignore[assignment]
        rule.path = empty(path_id, robot)
        command = rule.judge(scan, odom)
        said.append(None if command is None else (robot, path_id))
    assert said == [("r1", 5), ("r2", 6), None, None, ("r1", 7)]

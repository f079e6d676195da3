"""The shipped controller with the learned scenarios reading the model register: a strategy
names a registered (name, version), learned_drive runs that file and says so, and an UPDATE
of the strategy switches the model with no restart; a foresight model that cannot be loaded
stands foresight down while the strategy's other scenarios drive."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from common.contract import keys
from tests.contract.controller.conftest import Feeder, eventually
from tests.contract.controller.test_dwa import PERIOD_S, publish_path, shipped_controller
from tests.unit.learn.test_model_refusals import model_doc

__all__ = ["shipped_controller"]  # the fixture, imported to be found


def constant_model(path: Path, version: str, linear: float, angular: float) -> str:
    doc = model_doc(version=version)
    for layer in doc["layers"]:
        layer["w"] = np.zeros_like(np.asarray(layer["w"])).tolist()
    doc["layers"][-1]["b"] = [linear, angular]
    path.write_text(json.dumps(doc))
    return str(path)


async def register(feeder: Feeder, name: str, version: str, path: str) -> None:
    await feeder.conn.execute(
        "INSERT INTO model (name, version, path, metrics) VALUES ($1, $2, $3, '{}')",
        name,
        version,
        path,
    )
    feeder.notifier.notify(keys.MODEL, None, None)


async def newest(feeder: Feeder, source: str, since: int = 0) -> Any:
    async def check() -> Any:
        await feeder.odometry(0.0)
        await feeder.scan()
        await asyncio.sleep(PERIOD_S)
        rows = [r for r in await feeder.recommendations(source) if r["id"] > since]
        return rows[-1] if rows else None

    return await eventually(check, f"a recommendation from {source}")


async def test_a_registered_version_drives_and_an_update_switches_it(
    feeder: Feeder, shipped_controller: None, tmp_path: Path
) -> None:
    await register(feeder, "drive", "one", constant_model(tmp_path / "1.json", "one", 0.15, -0.4))
    await register(feeder, "drive", "two", constant_model(tmp_path / "2.json", "two", 0.1, 0.3))
    params = {"learned_model": "drive", "learned_model_version": "one"}
    await feeder.add_strategy("REGISTERED", ["learned_drive"], params)
    await feeder.set_strategy("REGISTERED")
    await publish_path(feeder, [0.0, 3.0], [0.0, 0.0])
    row = await newest(feeder, "learned_drive")
    assert (row["linear_mps"], row["angular_rps"]) == (pytest.approx(0.15), pytest.approx(-0.4))
    assert row["reason"].startswith("learned_drive: model tiny version one (registered), ")
    assert row["inputs"]["model_version"] == "one"

    await feeder.conn.execute(
        "UPDATE strategy SET params = $1 WHERE code = 'REGISTERED'",
        {**params, "learned_model_version": "two"},
    )
    feeder.notifier.notify(keys.STRATEGY, None, None)

    async def switched() -> Any:
        found = await newest(feeder, "learned_drive", row["id"])
        return found if found["inputs"]["model_version"] == "two" else None

    now = await eventually(switched, "the model switched to version two")
    assert (now["linear_mps"], now["angular_rps"]) == (pytest.approx(0.1), pytest.approx(0.3))


async def test_a_refused_foresight_model_stands_it_down_and_the_others_drive(
    feeder: Feeder, shipped_controller: None, tmp_path: Path
) -> None:
    broken = tmp_path / "broken.json"
    broken.write_text("{not a model")
    params = {"foresight_model": str(broken)}
    await feeder.add_strategy("FORESIGHT_BROKEN", ["foresight", "avoid_left"], params)
    await feeder.set_strategy("FORESIGHT_BROKEN")
    await publish_path(feeder, [0.0, 3.0], [0.0, 0.0])
    wall = (-20.0, 20.0, 0.3)  # ahead: avoid_left acts

    async def avoid() -> list[Any]:
        await feeder.odometry(0.0)
        await feeder.scan(wall)
        await asyncio.sleep(PERIOD_S)
        return list(await feeder.recommendations("avoid_left"))

    for _ in range(3):
        await eventually(avoid, "avoid_left")
    assert await feeder.recommendations("foresight") == []


async def test_foresight_recommends_its_manoeuvre_naming_its_model_and_p(
    feeder: Feeder, shipped_controller: None, tmp_path: Path
) -> None:
    from tests.unit.learn.test_foresight import foresight_doc

    path = tmp_path / "fear.json"
    path.write_text(json.dumps(foresight_doc(version="fear1", bias=4.0, weight=0.0)))
    await register(feeder, "fear", "fear1", str(path))
    await feeder.add_strategy("FORESEEING", ["foresight"], {"foresight_model": "fear"})
    await feeder.set_strategy("FORESEEING")
    path_id = await publish_path(feeder, [0.0, 3.0], [0.0, 0.0])
    row = await newest(feeder, "foresight")  # after a second of history
    assert row["priority"] == 60 and row["linear_mps"] == pytest.approx(-0.15)
    assert row["reason"].startswith(
        "foresight: model stopped version fear1 (registered): no progress within 3 s"
        " predicted, p 0.98 >= 0.60, confidence 1.00, with the robot stalled (under 0.25 m"
        " a second) for 1.5 s: backing up"
    )
    inputs = row["inputs"]
    assert inputs["model_version"] == "fear1" and inputs["planned_path"] == path_id
    assert inputs["p_no_progress"] == pytest.approx(0.982, abs=1e-3)

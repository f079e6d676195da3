"""The shipped controller with learned_drive (pnav_learned, found through its entry point),
against Postgres and Zenoh, fed as a foreign client would: a strategy naming learned_drive
and a model file, a planned_path row, odometry and scans."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.contract.controller.conftest import Feeder, eventually
from tests.contract.controller.test_dwa import PERIOD_S, publish_path, shipped_controller
from tests.unit.learn.test_model_refusals import model_doc

__all__ = ["shipped_controller"]  # the fixture, imported to be found


def constant_model(path: Path, linear: float, angular: float) -> str:
    """A model that predicts (linear, angular) whatever it sees: zero weights, those biases."""
    doc = model_doc(version="const1")
    for layer in doc["layers"]:
        layer["w"] = np.zeros_like(np.asarray(layer["w"])).tolist()
    doc["layers"][-1]["b"] = [linear, angular]
    path.write_text(json.dumps(doc))
    return str(path)


async def rows_of(feeder: Feeder, *sources: str) -> list[Any]:
    async def check() -> list[Any]:
        await feeder.odometry(0.0)
        await feeder.scan()
        await asyncio.sleep(PERIOD_S)
        return list(await feeder.recommendations(*sources))

    return await eventually(check, f"a recommendation from {sources}")


async def test_learned_drive_recommends_what_its_model_predicts_and_says_which(
    feeder: Feeder, shipped_controller: None, tmp_path: Path
) -> None:
    model = constant_model(tmp_path / "m.json", 0.15, -0.4)
    params = {"learned_model": model, "learned_model_version": "const1"}
    await feeder.add_strategy("LEARNED", ["learned_drive"], params)
    await feeder.set_strategy("LEARNED")
    path = await publish_path(feeder, [0.0, 3.0], [0.0, 0.0])
    row = (await rows_of(feeder, "learned_drive"))[0]
    assert row["kind"] == "robot" and row["priority"] == 30
    assert (row["linear_mps"], row["angular_rps"]) == (
        pytest.approx(0.15),
        pytest.approx(-0.4),
    )
    assert row["reason"].startswith("learned_drive: model tiny version const1, confidence ")
    # the proposal was put to dwa's check (pnav_learned.candidates) and passed as it was
    assert "proposed 0.15 m/s, -0.40 rad/s; admissible" in row["reason"]
    inputs = row["inputs"]
    assert inputs["planned_path"] == path and inputs["model_version"] == "const1"
    assert inputs["admissible"] is True and inputs["checked"] == 1


async def test_a_refused_model_stands_learned_drive_down_and_the_others_drive(
    feeder: Feeder, shipped_controller: None, tmp_path: Path
) -> None:
    params = {"learned_model": str(tmp_path / "missing.json")}
    await feeder.add_strategy("LEARNED_BROKEN", ["learned_drive", "avoid_left"], params)
    await feeder.set_strategy("LEARNED_BROKEN")
    await publish_path(feeder, [0.0, 3.0], [0.0, 0.0])
    wall = (-20.0, 20.0, 0.3)  # ahead: avoid_left acts

    async def avoid() -> list[Any]:
        await feeder.odometry(0.0)
        await feeder.scan(wall)
        await asyncio.sleep(PERIOD_S)
        return list(await feeder.recommendations("avoid_left"))

    for _ in range(3):
        await eventually(avoid, "avoid_left")
    assert await feeder.recommendations("learned_drive") == []

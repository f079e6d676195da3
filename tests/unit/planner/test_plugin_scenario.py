"""A move scenario from a package of its own: found through its entry point, run by the
planner, with no edit to any planner file (docs/PLANNER.md, "Adding a move scenario")."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from services.planner import meta
from tests.unit.planner.harness import Planner

MODULE = "pnav_test_creep_scenario"

SOURCE = '''
from common.planner_core.scenario import Movement, MoveScenario


class Creep(MoveScenario):
    """Creeps straight ahead, whatever the heading error."""

    scenario = "creep"

    def select(self, error, remaining_m, info, turn_rate=0.0):
        return Movement(0.05, 0.0, False)
'''


@pytest.fixture
def creep_installed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The package as pip would leave it in site-packages: the module, and a dist-info
    whose entry_points.txt registers the scenario under the planner's group."""
    (tmp_path / f"{MODULE}.py").write_text(SOURCE)
    info = tmp_path / f"{MODULE}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {MODULE}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[{meta.SCENARIO_GROUP}]\ncreep = {MODULE}:Creep\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    yield
    sys.modules.pop(MODULE, None)


@pytest.mark.usefixtures("creep_installed")
async def test_an_installed_scenario_package_is_found_and_run() -> None:
    found = meta.move_scenarios()
    assert list(found) == ["turn_then_move", "move_while_turning", "creep"]
    creep = {"code": "CREEP", "planner_scenario": "creep", "params": {"target": "goal"}}
    p = Planner(found, (creep,))
    p.strategy("CREEP")
    p.goal(0.0, 2.0)  # to the left: a shipped scenario would turn first
    await p.tick()
    assert p.running()["move"] == ("Creep", "CREEP")
    await p.tick()
    said = p.recommendations("creep")
    assert [(r["linear_mps"], r["angular_rps"]) for r in said] == [(0.05, 0.0)]
    assert said[0]["inputs"]["strategy"] == "CREEP"


def test_without_the_package_the_scenario_is_unknown() -> None:
    assert "creep" not in meta.move_scenarios()

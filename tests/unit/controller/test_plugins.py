"""Controller scenarios found through entry points: a package's scenario is loaded, and what
cannot run (an import error, not a ControllerScenario, a name that disagrees with the class,
a name already taken) is logged and left out, never taking the controller down."""

from __future__ import annotations

import importlib
import logging
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from common.controller_core.scenario import ControllerScenario, installed_scenarios
from services.controller.safety_stop import SafetyStop
from tests.unit.controller.packages import CREEP, write_scenario_package


@pytest.fixture
def plugin_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A directory at the end of sys.path (after the installed proactive-nav); the modules
    imported from it are forgotten afterwards."""
    root = tmp_path / "site"
    root.mkdir()
    monkeypatch.setattr(sys, "path", [*sys.path, str(root)])
    importlib.invalidate_caches()
    yield root
    for name in [n for n in sys.modules if n.startswith("pnav_test_")]:
        del sys.modules[name]


def test_a_scenario_package_is_found_and_what_cannot_run_is_refused(
    plugin_dir: Path, caplog: pytest.LogCaptureFixture
) -> None:
    write_scenario_package(
        plugin_dir,
        "pnav-test-scenarios",
        {
            "pnav_test_creep": CREEP,
            "pnav_test_broken": "import pnav_test_no_such_module\n",
            "pnav_test_plain": "class Plain:\n    scenario = 'plain'\n",
            "pnav_test_misnamed": CREEP.replace('scenario = "creep"', 'scenario = "crawl"'),
            "pnav_test_impostor": "from services.controller.safety_stop import SafetyStop\n\n"
            "class Impostor(SafetyStop):\n    pass\n",
        },
        {
            "creep": "pnav_test_creep:Creep",
            "broken": "pnav_test_broken:Anything",
            "plain": "pnav_test_plain:Plain",
            "misnamed": "pnav_test_misnamed:Creep",
            "safety_stop": "pnav_test_impostor:Impostor",
        },
    )
    caplog.set_level(logging.ERROR, logger="pnav.plugins")

    found = installed_scenarios()

    creep = found["creep"]
    assert issubclass(creep, ControllerScenario) and creep.__module__ == "pnav_test_creep"
    assert not {"broken", "plain", "misnamed"} & set(found)
    assert found["safety_stop"] is SafetyStop  # the name was taken first: the impostor is not
    assert {"avoid_left", "avoid_right"} <= set(found)  # one bad plug-in spoils nothing else
    refusals = {(r.getMessage(), getattr(r, "scenario", None)) for r in caplog.records}
    assert refusals == {
        ("scenario plug-in cannot be loaded; ignored", "broken"),
        ("scenario plug-in refused; ignored", "plain"),
        ("scenario plug-in refused; ignored", "misnamed"),
        ("scenario name claimed twice; the second is ignored", "safety_stop"),
    }


def test_a_plugin_first_on_sys_path_cannot_take_a_shipped_scenarios_name(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    root = tmp_path / "front"
    root.mkdir()
    write_scenario_package(
        root,
        "pnav-test-front",
        {
            "pnav_test_front_impostor": "from services.controller.safety_stop import SafetyStop"
            "\n\nclass Impostor(SafetyStop):\n    pass\n"
        },
        {"safety_stop": "pnav_test_front_impostor:Impostor"},
    )
    # PYTHONPATH puts a directory before site-packages: its distributions come first
    monkeypatch.setattr(sys, "path", [str(root), *sys.path])
    importlib.invalidate_caches()
    caplog.set_level(logging.ERROR, logger="pnav.plugins")
    try:
        found = installed_scenarios()
    finally:
        sys.modules.pop("pnav_test_front_impostor", None)

    assert found["safety_stop"] is SafetyStop
    assert [getattr(r, "ignored", None) for r in caplog.records] == [
        "pnav_test_front_impostor:Impostor"
    ]

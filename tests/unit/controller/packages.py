"""A scenario package written to a directory, as ``pip install`` would leave it: its modules
and a ``*.dist-info`` whose entry_points.txt names the scenarios. importlib.metadata finds
it on ``sys.path`` (or PYTHONPATH), like any installed distribution."""

from __future__ import annotations

from pathlib import Path

from common.controller_core.scenario import SCENARIO_GROUP


def write_scenario_package(
    root: Path, dist: str, modules: dict[str, str], scenarios: dict[str, str]
) -> Path:
    """Write ``modules`` (name -> source) and distribution ``dist`` naming ``scenarios``
    (scenario name -> ``module:Class``) under ``root``; returns ``root``."""
    root.mkdir(parents=True, exist_ok=True)
    for name, source in modules.items():
        (root / f"{name}.py").write_text(source)
    info = root / f"{dist}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.1\n")
    lines = [f"[{SCENARIO_GROUP}]", *(f"{name} = {target}" for name, target in scenarios.items())]
    (info / "entry_points.txt").write_text("\n".join(lines) + "\n")
    return root


# A complete controller scenario in one module: drive on slowly whatever the scan shows.
CREEP = """
from common.controller_core.scenario import Command, ControllerScenario


class Creep(ControllerScenario):
    scenario = "creep"
    priority = 5

    @classmethod
    def decide(cls, scan, odom, robot, params):
        return Command(0.03, 0.0, f"creeping on scan {scan.id}")
"""

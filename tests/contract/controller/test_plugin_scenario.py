"""A controller scenario from a package of its own: the shipped controller, started as its
container starts it, finds it through the ``pnav.controller.scenarios`` entry points and
runs it for a strategy that names it, with no edit to any file of the controller's."""

from __future__ import annotations

from importlib.metadata import entry_points
from pathlib import Path

import pytest

from common.config import ZenohSettings
from tests.contract.controller.conftest import Feeder, controller_process
from tests.contract.controller.test_controller import scans_until
from tests.unit.controller.packages import CREEP, write_scenario_package


async def test_a_scenario_installed_as_a_package_recommends(
    feeder: Feeder, db_url: str, zenoh_settings: ZenohSettings, tmp_path: Path
) -> None:
    site = write_scenario_package(
        tmp_path / "site", "pnav-creep", {"pnav_creep": CREEP}, {"creep": "pnav_creep:Creep"}
    )
    await feeder.odometry(0.0)
    await feeder.add_strategy("CREEP", ["creep"], {})
    await feeder.set_strategy("CREEP")
    log = tmp_path / "controller.log"
    async with controller_process("services.controller", db_url, zenoh_settings, log, site):
        rows = await scans_until(feeder, (), "creep")
    row = rows[0]
    assert (row["kind"], row["priority"]) == ("robot", 5)
    assert (row["linear_mps"], row["angular_rps"]) == (pytest.approx(0.03), 0.0)
    assert row["reason"] == f"creeping on scan {row['inputs']['laser_scan']}"
    assert row["expires_stamp"] - row["stamp"] == pytest.approx(0.5)
    # it says at start which scenarios it found
    installed = {e.name for e in entry_points(group="pnav.controller.scenarios")}
    names = ",".join(sorted(installed | {"creep"}))
    assert f"controller scenarios names={names}" in log.read_text()

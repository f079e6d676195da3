"""The meta-controller tick by tick (as py_trees' tests go): one engine activation per step,
on the in-memory contract through the real store, the expected state written beside each.

A step's state: which (robot, scenario) pairs run (the supervisor's behaviours), which rules
wait in the queue for the next activation, and which scenarios recommended during it.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any

import pytest

from common.contract.records import LaserScan, Odometry, Robot, Strategy
from common.controller_core.scenario import Command, ControllerScenario
from services.controller.avoid_left import AvoidLeft
from services.controller.safety_stop import SafetyStop
from tests.unit.controller.rig import Rig

RIGHT = (-40.0, -20.0, 0.30)  # front-right, within the avoid distance: avoid_left fires


class Blurt(ControllerScenario):
    """Recommends ``params["speed"]`` on every fresh scan; its actions fail after the write
    on the scan id ``params["fail_on_scan"]`` names."""

    scenario = "blurt"
    priority = 10

    @classmethod
    def decide(
        cls, scan: LaserScan, odom: Odometry | None, robot: Robot, params: Mapping[str, Any]
    ) -> Command | None:
        return Command(float(params.get("speed", 0.1)), 0.0, "blurt")

    async def actions(self) -> None:
        await super().actions()
        if self.scan is not None and self.scan.id == self.spec.params.get("fail_on_scan"):
            raise RuntimeError("failed after the write")


SCENARIOS = {"avoid_left": AvoidLeft, "blurt": Blurt, "safety_stop": SafetyStop}
TWO = Strategy("TWO", None, ("avoid_left", "blurt"), {})
OTHER = Strategy("OTHER", None, ("blurt", "safety_stop"), {})
ONE = Strategy("ONE", None, ("blurt",), {})


@pytest.fixture
def rig() -> Rig:
    return Rig(scenarios=SCENARIOS)


async def test_a_strategy_naming_two_scenarios_starts_both(rig: Rig) -> None:
    rig.set_strategy("r1", TWO)
    assert await rig.tick() == []  # the meta starts both; they run from the next activation
    assert rig.running() == [("r1", "avoid_left"), ("r1", "blurt")]
    assert rig.queued() == ["AvoidLeft", "Blurt", "MetaController"]
    rig.new_scan(RIGHT)
    assert sorted(await rig.tick()) == ["avoid_left", "blurt"]  # both, on scan 1
    assert await rig.tick() == []  # no new scan: nothing
    assert rig.queued() == ["AvoidLeft", "Blurt", "MetaController"]  # they live on
    assert rig.state.supervisor.started == 2


async def test_a_strategy_switch_ends_one_scenario_and_starts_another(rig: Rig) -> None:
    rig.set_strategy("r1", TWO)
    await rig.tick()  # running: avoid_left, blurt
    blurt = rig.state.supervisor.running[("r1", "blurt")]
    rig.set_strategy("r1", OTHER)
    rig.new_scan(RIGHT)
    # the meta runs first: avoid_left ends before it reads the scan, safety_stop starts
    assert await rig.tick() == ["blurt"]
    assert rig.running() == [("r1", "blurt"), ("r1", "safety_stop")]
    assert rig.queued() == ["Blurt", "MetaController", "SafetyStop"]  # AvoidLeft not queued again
    assert rig.state.supervisor.running[("r1", "blurt")] is blurt  # blurt went on untouched
    assert (rig.state.supervisor.started, rig.state.supervisor.ended) == (3, 1)


async def test_a_params_change_updates_a_running_scenario_in_place(rig: Rig) -> None:
    rig.set_strategy("r1", ONE)
    await rig.tick()  # running: blurt at the default speed
    blurt = rig.state.supervisor.running[("r1", "blurt")]
    rig.set_strategy("r1", Strategy("ONE", None, ("blurt",), {"speed": 0.3}))
    rig.new_scan()
    assert await rig.tick() == ["blurt"]  # same rule, new params, in this very activation
    assert rig.state.supervisor.running[("r1", "blurt")] is blurt
    assert blurt.spec.params == {"speed": 0.3}
    assert rig.recommendations()[-1]["linear_mps"] == 0.3
    assert (rig.state.supervisor.started, rig.state.supervisor.ended) == (1, 0)


async def test_a_rule_raising_in_its_actions_restarts_and_remembers_its_last_scan(
    rig: Rig,
) -> None:
    rig.set_strategy("r1", Strategy("ONE", None, ("blurt",), {"fail_on_scan": 1}))
    await rig.tick()  # running: blurt
    first = rig.state.supervisor.running[("r1", "blurt")]
    assert rig.new_scan() == 1
    assert await rig.tick() == ["blurt"]  # wrote on scan 1, then raised: rule discarded
    assert first.lost and rig.queued() == ["MetaController"]
    assert await rig.tick() == []  # the meta's next run starts it again
    second = rig.state.supervisor.running[("r1", "blurt")]
    assert second is not first and rig.state.supervisor.restarted == 1
    assert rig.queued() == ["Blurt", "MetaController"]
    assert await rig.tick() == []  # scan 1 again: already recommended on, not twice
    rig.new_scan()
    assert await rig.tick() == ["blurt"]  # scan 2: as before the failure
    assert rig.state.supervisor.restarted == 1


async def test_a_robot_lost_to_another_replica_has_its_scenarios_ended(rig: Rig) -> None:
    rig.add_robot(Robot("r2", 0.22, 2.84, 0.105, 19.98))
    rig.set_strategy("r1", TWO)
    rig.set_strategy("r2", ONE)
    await rig.tick()
    assert rig.running() == [("r1", "avoid_left"), ("r1", "blurt"), ("r2", "blurt")]
    rig.new_scan(robot_id="r2")
    assert await rig.tick() == ["blurt"]  # r2's
    # another replica takes r2: what ControllerService.on_ownership_change does
    rig.owned = {"r1"}
    rig.store.forget({"r2"})
    assert rig.store.last_recommended_scan("r2", "blurt") is None
    rig.new_scan(robot_id="r2")
    rig.new_scan(robot_id="r1")
    assert await rig.tick() == ["blurt"]  # r1's only: r2's blurt ended before its scan
    assert rig.running() == [("r1", "avoid_left"), ("r1", "blurt")]
    assert rig.recommendations()[-1]["robot_id"] == "r1"
    assert rig.state.supervisor.ended == 1


async def test_an_unknown_scenario_is_ignored_and_warned_about_once(
    rig: Rig, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="pnav.controller")

    def warnings() -> int:
        return [r.getMessage() for r in caplog.records].count("unknown controller scenario ignored")

    rig.set_strategy("r1", Strategy("ODD", None, ("blurt", "dance"), {}))
    await rig.tick()
    assert (rig.running(), warnings()) == ([("r1", "blurt")], 1)
    for _ in range(3):
        await rig.tick()
    assert (rig.running(), warnings()) == ([("r1", "blurt")], 1)  # once per name
    rig.set_strategy("r1", Strategy("ODDER", None, ("dance",), {}))
    await rig.tick()
    assert (rig.running(), warnings()) == ([], 1)  # another strategy naming it: still once

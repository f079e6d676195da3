"""The meta-controller and the scenario rules in a real Engine, tick by tick, on the
in-memory contract through the real store: which scenarios run, once per scan, freshness,
switches."""

from __future__ import annotations

import logging
from collections.abc import Iterable
from typing import Any

import pytest

from common.contract.records import Robot, Strategy
from common.controller_core.scenario import Command, installed_scenarios
from common.engine import Rule
from pnav.monolith.contract import MemoryContract
from pnav.monolith.memory_controller import MemoryControllerSource
from services.controller.avoid_left import AvoidLeft
from services.controller.avoid_right import AvoidRight
from services.controller.safety_stop import SafetyStop
from services.controller.store import ScanAndOdometry
from tests.unit.controller.rig import Rig

AVOID = Strategy("GOTO_AVOID", "turn_then_move", ("avoid_left", "avoid_right", "safety_stop"), {})
DIRECT = Strategy("GOTO_DIRECT", "turn_then_move", ("safety_stop",), {})
IDLE = Strategy("IDLE", None, (), {})
RIGHT_OBSTACLE = (-40.0, -20.0, 0.30)


@pytest.fixture
def rig() -> Rig:
    return Rig()


async def test_the_strategy_starts_its_scenarios_which_recommend_once_per_scan(rig: Rig) -> None:
    rig.set_strategy("r1", AVOID)
    rig.new_scan(RIGHT_OBSTACLE)
    assert await rig.tick() == []  # the meta-controller starts the three scenarios
    assert sorted(key[1] for key in rig.running()) == sorted(AVOID.controller_scenarios)
    assert await rig.tick() == ["avoid_left"]
    assert await rig.tick() == []  # same scan: not again
    second = rig.new_scan(RIGHT_OBSTACLE)
    assert await rig.tick() == ["avoid_left"]
    rec = rig.recommendations()[-1]
    assert (rec["priority"], rec["expires_stamp"] - rec["stamp"], rec["stamp"]) == (50, 0.5, 10.0)
    assert rec["inputs"] == {"laser_scan": second, "scan_stamp": 10.0} and second == 2
    assert rec["angular_rps"] > 0
    rig.new_scan()
    assert await rig.tick() == []  # clear


async def test_safety_stop_records_the_odometry_it_used(rig: Rig) -> None:
    rig.set_strategy("r1", DIRECT)
    odometry = rig.odometry(0.15, stamp=9.98)
    rig.new_scan((-10, 10, 0.14), (-40, -20, 0.3))
    await rig.tick()
    assert await rig.tick() == ["safety_stop"]  # and no avoidance under GOTO_DIRECT
    rec = rig.recommendations()[-1]
    assert (rec["priority"], rec["linear_mps"]) == (100, 0.0)
    assert rec["inputs"] == {
        "laser_scan": 1,
        "scan_stamp": 10.0,
        "odometry": odometry,
        "odometry_stamp": 9.98,
    }
    rig.odometry(0.0, 0.8)  # now turning in place
    rig.new_scan((-10, 10, 0.14))
    assert await rig.tick() == []


async def test_a_strategy_switch_ends_and_starts_scenarios_without_restart(rig: Rig) -> None:
    rig.set_strategy("r1", AVOID)
    rig.odometry(0.15)
    await rig.tick()
    rig.new_scan((-10, 10, 0.14), (-40, -20, 0.3))
    assert sorted(await rig.tick()) == ["avoid_left", "safety_stop"]
    rig.set_strategy("r1", DIRECT)
    rig.new_scan((-10, 10, 0.14), (-40, -20, 0.3))
    assert await rig.tick() == ["safety_stop"]  # the meta ran first: avoid_* ended at once
    assert [key[1] for key in rig.running()] == ["safety_stop"]
    await rig.tick()
    assert {type(r).__name__ for r in rig.engine.current} == {"MetaController", "SafetyStop"}
    rig.set_strategy("r1", IDLE)
    rig.new_scan((-10, 10, 0.14), (-40, -20, 0.3))
    assert await rig.tick() == []
    assert rig.running() == []
    rig.set_strategy("r1", AVOID)
    await rig.tick()
    assert sorted(await rig.tick()) == ["avoid_left", "safety_stop"]  # back, on the same scan


async def test_a_restarted_scenario_does_not_reuse_a_scan(rig: Rig) -> None:
    rig.set_strategy("r1", AVOID)
    rig.new_scan(RIGHT_OBSTACLE)
    await rig.tick()
    assert await rig.tick() == ["avoid_left"]
    rig.set_strategy("r1", IDLE)
    await rig.tick()
    rig.set_strategy("r1", AVOID)
    await rig.tick()
    assert await rig.tick() == []  # that scan was already used by avoid_left


async def test_stale_scans_and_a_missing_clock_recommend_nothing(rig: Rig) -> None:
    rig.set_strategy("r1", AVOID)
    rig.new_scan(RIGHT_OBSTACLE, age_s=2.0)
    await rig.tick()
    assert await rig.tick() == []
    rig.now = None
    rig.new_scan(RIGHT_OBSTACLE)
    assert await rig.tick() == []
    rig.now = 10.0
    assert await rig.tick() == ["avoid_left"]  # fresh once the clock is known


async def test_params_and_limits_follow_the_strategy_at_run_time(rig: Rig) -> None:
    rig.set_strategy("r1", AVOID)
    await rig.tick()
    rig.set_strategy(
        "r1", Strategy("TIMID", None, AVOID.controller_scenarios, {"avoid_distance_m": 0.2})
    )
    rig.new_scan(RIGHT_OBSTACLE)
    assert await rig.tick() == []  # 0.30 m is beyond the new 0.2 m
    rig.set_strategy("r1", AVOID)
    rig.new_scan(RIGHT_OBSTACLE)
    assert await rig.tick() == ["avoid_left"]


async def test_unknown_scenarios_are_logged_once_and_ignored(
    rig: Rig, caplog: pytest.LogCaptureFixture
) -> None:
    rig.set_strategy("r1", Strategy("ODD", None, ("avoid_left", "dance"), {}))
    caplog.set_level(logging.WARNING, logger="pnav.controller")
    rig.new_scan(RIGHT_OBSTACLE)
    await rig.tick()
    assert await rig.tick() == ["avoid_left"]
    for _ in range(3):
        await rig.tick()
    assert [r.getMessage() for r in caplog.records].count(
        "unknown controller scenario ignored"
    ) == 1
    assert [key[1] for key in rig.running()] == ["avoid_left"]


async def test_robots_each_get_their_own_scenarios(rig: Rig) -> None:
    rig.add_robot(Robot("r2", 0.22, 2.84, 0.105, 19.98))
    rig.set_strategy("r1", AVOID)
    rig.set_strategy("r2", DIRECT)
    await rig.tick()
    assert rig.running() == [
        ("r1", "avoid_left"),
        ("r1", "avoid_right"),
        ("r1", "safety_stop"),
        ("r2", "safety_stop"),
    ]
    rig.remove_robot("r2")  # a robot that leaves ends its scenarios
    await rig.tick()
    assert all(robot == "r1" for robot, _ in rig.running())


class RestartingDatabase(MemoryControllerSource):
    """The in-memory contract, whose next scan read fails as a restarting Postgres does."""

    def __init__(self, contract: MemoryContract) -> None:
        super().__init__(contract)
        self.error: Exception | None = None

    async def newest_scan_and_odometry(self, robot_id: str) -> ScanAndOdometry:
        if self.error is not None:
            error, self.error = self.error, None
            raise error
        return await super().newest_scan_and_odometry(robot_id)


async def test_a_rule_lost_to_an_error_is_replaced() -> None:
    rig = Rig(source=RestartingDatabase)
    assert isinstance(rig.source, RestartingDatabase)
    rig.set_strategy("r1", DIRECT)
    rig.odometry(0.15)
    await rig.tick()
    rig.source.error = ConnectionError("database restarting")
    await rig.tick()  # safety_stop's data acquisition fails: the engine discards the rule
    assert not any(isinstance(r, SafetyStop) for r in rig.engine.current)
    await rig.tick()  # the meta-controller's next run starts it again
    assert rig.state.supervisor.restarted == 1
    assert any(isinstance(r, SafetyStop) for r in rig.engine.current)
    rig.new_scan((-10, 10, 0.14))
    assert await rig.tick() == ["safety_stop"]


def test_the_installed_scenarios_name_every_builtin() -> None:
    found = installed_scenarios()
    assert {name: found[name] for name in ("avoid_left", "avoid_right", "safety_stop")} == {
        "avoid_left": AvoidLeft,
        "avoid_right": AvoidRight,
        "safety_stop": SafetyStop,
    }


class Brittle(SafetyStop):
    """safety_stop, whose policy fails on every scan."""

    @classmethod
    def decide(cls, *args: Any) -> Command | None:
        raise ZeroDivisionError("a bug in the policy")


async def test_a_policy_error_counts_as_a_false_condition_and_the_rule_lives_on() -> None:
    rig = Rig(scenarios={"safety_stop": Brittle})
    rig.set_strategy("r1", DIRECT)
    await rig.tick()
    rig.odometry(0.15)
    rig.new_scan((-10, 10, 0.14))
    assert await rig.tick() == []
    assert rig.engine.stats_for(Brittle).errors == 1  # logged and counted, as a test
    assert rig.queued() == ["Brittle", "MetaController"]  # not discarded: no restart
    assert rig.state.supervisor.restarted == 0


def verdict(rule: Rule) -> tuple[bool, bool]:
    """The guards and the conditions, AND-ed as the engine does."""

    def held(tests: bool | Iterable[bool]) -> bool:
        return tests if isinstance(tests, bool) else all(tests)

    return held(rule.activation_guards()), held(rule.conditions())


async def test_the_guards_and_conditions_only_test(rig: Rig) -> None:
    rig.set_strategy("r1", AVOID)
    rig.odometry(0.15)
    await rig.tick()  # the three scenarios start
    rig.set_strategy("r1", DIRECT)  # the meta has work: end avoid_left and avoid_right
    rig.new_scan((-10, 10, 0.14), RIGHT_OBSTACLE)  # and safety_stop, avoid_left a command
    rules = list(rig.engine.current)
    verdicts = []
    for rule in rules:
        await rule.data_acquisition()
        before = (dict(vars(rule)), rig.running())
        verdicts.append(verdict(rule))
        assert verdict(rule) == verdicts[-1]  # asked again: the same answer
        assert (dict(vars(rule)), rig.running()) == before  # and nothing changed
    by_name = dict(zip([type(rule).__name__ for rule in rules], verdicts, strict=True))
    assert by_name == {
        "MetaController": (True, True),
        "AvoidLeft": (True, True),
        "AvoidRight": (True, False),
        "SafetyStop": (True, True),
    }

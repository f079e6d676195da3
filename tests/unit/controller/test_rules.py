"""The meta-controller and the scenario rules in a real Engine, tick by tick, against an
in-memory host (no database): which scenarios run, once per scan, freshness, switches."""

from __future__ import annotations

import logging

import pytest

from common.contract.records import ActiveStrategy, LaserScan, Odometry, Robot, Strategy
from common.engine import Engine
from services.controller.meta import STALL_LIMIT, ControllerState, MetaController
from services.controller.registry import SCENARIOS, register
from services.controller.safety_stop import SafetyStop
from services.controller.scenario import Recommendation
from tests.unit.controller.scans import BURGER, odom, scan

AVOID = Strategy("GOTO_AVOID", "turn_then_move", ("avoid_left", "avoid_right", "safety_stop"), {})
DIRECT = Strategy("GOTO_DIRECT", "turn_then_move", ("safety_stop",), {})
IDLE = Strategy("IDLE", None, (), {})
RIGHT_OBSTACLE = (-40.0, -20.0, 0.30)


class FakeHost:
    def __init__(self) -> None:
        self.now: float | None = 10.0
        self.robot_rows: list[Robot] = [BURGER]
        self.strategy: dict[str, Strategy] = {}
        self.scans: dict[str, LaserScan] = {}
        self.odometry: dict[str, Odometry] = {}
        self.written: list[Recommendation] = []
        self.scan_error: Exception | None = None

    def sim_now(self) -> float | None:
        return self.now

    async def robots(self) -> list[Robot]:
        return list(self.robot_rows)

    async def active_strategies(self) -> dict[str, ActiveStrategy]:
        return {r: ActiveStrategy(r, s, None, "user") for r, s in self.strategy.items()}

    async def newest_scan(self, robot_id: str) -> LaserScan | None:
        if self.scan_error is not None:
            error, self.scan_error = self.scan_error, None
            raise error
        return self.scans.get(robot_id)

    async def newest_odometry(self, robot_id: str) -> Odometry | None:
        return self.odometry.get(robot_id)

    async def recommend(self, recommendation: Recommendation) -> int:
        self.written.append(recommendation)
        return len(self.written)


class Rig:
    """An engine seeded with the meta-controller; ``tick()`` runs one activation and returns
    the sources that recommended during it."""

    def __init__(self) -> None:
        self.host = FakeHost()
        self.state = ControllerState()
        self.engine = Engine()
        self.engine.add_meta(lambda: MetaController(self.host, self.state))
        self.scan_id = 0

    def new_scan(self, *obstacles: tuple[float, float, float], age_s: float = 0.0) -> None:
        self.scan_id += 1
        now = 10.0 if self.host.now is None else self.host.now
        self.host.scans["r1"] = scan(*obstacles, scan_id=self.scan_id, stamp=now - age_s)

    async def tick(self) -> list[str]:
        before = len(self.host.written)
        await self.engine.activation()
        return [r.source for r in self.host.written[before:]]


@pytest.fixture
def rig() -> Rig:
    return Rig()


async def test_the_strategy_starts_its_scenarios_which_recommend_once_per_scan(rig: Rig) -> None:
    rig.host.strategy["r1"] = AVOID
    rig.new_scan(RIGHT_OBSTACLE)
    assert await rig.tick() == []  # the meta-controller starts the three scenarios
    assert sorted(key[1] for key in rig.state.running) == sorted(AVOID.controller_scenarios)
    assert await rig.tick() == ["avoid_left"]
    assert await rig.tick() == []  # same scan: not again
    rig.new_scan(RIGHT_OBSTACLE)
    assert await rig.tick() == ["avoid_left"]
    rec = rig.host.written[-1]
    assert (rec.priority, rec.ttl_s, rec.stamp) == (50, 0.5, 10.0)
    assert rec.inputs == {"laser_scan": 2, "scan_stamp": 10.0}
    assert rec.angular > 0
    rig.new_scan()
    assert await rig.tick() == []  # clear


async def test_safety_stop_records_the_odometry_it_used(rig: Rig) -> None:
    rig.host.strategy["r1"] = DIRECT
    rig.host.odometry["r1"] = odom(0.15, odom_id=7, stamp=9.98)
    rig.new_scan((-10, 10, 0.14), (-40, -20, 0.3))
    await rig.tick()
    assert await rig.tick() == ["safety_stop"]  # and no avoidance under GOTO_DIRECT
    rec = rig.host.written[-1]
    assert (rec.priority, rec.linear) == (100, 0.0)
    assert rec.inputs == {
        "laser_scan": 1,
        "scan_stamp": 10.0,
        "odometry": 7,
        "odometry_stamp": 9.98,
    }
    rig.host.odometry["r1"] = odom(0.0, 0.8, odom_id=8)  # now turning in place
    rig.new_scan((-10, 10, 0.14))
    assert await rig.tick() == []


async def test_a_strategy_switch_ends_and_starts_scenarios_without_restart(rig: Rig) -> None:
    rig.host.strategy["r1"] = AVOID
    rig.host.odometry["r1"] = odom(0.15)
    await rig.tick()
    rig.new_scan((-10, 10, 0.14), (-40, -20, 0.3))
    assert sorted(await rig.tick()) == ["avoid_left", "safety_stop"]
    rig.host.strategy["r1"] = DIRECT
    rig.new_scan((-10, 10, 0.14), (-40, -20, 0.3))
    assert await rig.tick() == ["safety_stop"]  # the meta ran first: avoid_* ended at once
    assert [key[1] for key in rig.state.running] == ["safety_stop"]
    await rig.tick()
    assert {type(r).__name__ for r in rig.engine.current} == {"MetaController", "SafetyStop"}
    rig.host.strategy["r1"] = IDLE
    rig.new_scan((-10, 10, 0.14), (-40, -20, 0.3))
    assert await rig.tick() == []
    assert rig.state.running == {}
    rig.host.strategy["r1"] = AVOID
    await rig.tick()
    assert sorted(await rig.tick()) == ["avoid_left", "safety_stop"]  # back, on the same scan


async def test_a_restarted_scenario_does_not_reuse_a_scan(rig: Rig) -> None:
    rig.host.strategy["r1"] = AVOID
    rig.new_scan(RIGHT_OBSTACLE)
    await rig.tick()
    assert await rig.tick() == ["avoid_left"]
    rig.host.strategy["r1"] = IDLE
    await rig.tick()
    rig.host.strategy["r1"] = AVOID
    await rig.tick()
    assert await rig.tick() == []  # that scan was already used by avoid_left


async def test_stale_scans_and_a_missing_clock_recommend_nothing(rig: Rig) -> None:
    rig.host.strategy["r1"] = AVOID
    rig.new_scan(RIGHT_OBSTACLE, age_s=2.0)
    await rig.tick()
    assert await rig.tick() == []
    rig.host.now = None
    rig.new_scan(RIGHT_OBSTACLE)
    assert await rig.tick() == []
    rig.host.now = 10.0
    assert await rig.tick() == ["avoid_left"]  # fresh once the clock is known


async def test_params_and_limits_follow_the_strategy_at_run_time(rig: Rig) -> None:
    rig.host.strategy["r1"] = AVOID
    await rig.tick()
    rig.host.strategy["r1"] = Strategy(
        "TIMID", None, AVOID.controller_scenarios, {"avoid_distance_m": 0.2}
    )
    rig.new_scan(RIGHT_OBSTACLE)
    assert await rig.tick() == []  # 0.30 m is beyond the new 0.2 m
    rig.host.strategy["r1"] = AVOID
    rig.new_scan(RIGHT_OBSTACLE)
    assert await rig.tick() == ["avoid_left"]


async def test_unknown_scenarios_are_logged_once_and_ignored(
    rig: Rig, caplog: pytest.LogCaptureFixture
) -> None:
    rig.host.strategy["r1"] = Strategy("ODD", None, ("avoid_left", "dance"), {})
    caplog.set_level(logging.WARNING, logger="pnav.controller")
    rig.new_scan(RIGHT_OBSTACLE)
    await rig.tick()
    assert await rig.tick() == ["avoid_left"]
    for _ in range(3):
        await rig.tick()
    assert [r.getMessage() for r in caplog.records].count(
        "unknown controller scenario ignored"
    ) == 1
    assert [key[1] for key in rig.state.running] == ["avoid_left"]


async def test_robots_each_get_their_own_scenarios(rig: Rig) -> None:
    r2 = Robot("r2", 0.22, 2.84, 0.105, 19.98)
    rig.host.robot_rows.append(r2)
    rig.host.strategy.update(r1=AVOID, r2=DIRECT)
    await rig.tick()
    assert sorted(rig.state.running) == [
        ("r1", "avoid_left"),
        ("r1", "avoid_right"),
        ("r1", "safety_stop"),
        ("r2", "safety_stop"),
    ]
    rig.host.robot_rows.remove(r2)  # a robot that leaves ends its scenarios
    await rig.tick()
    assert all(robot == "r1" for robot, _ in rig.state.running)


async def test_a_rule_lost_to_an_error_is_replaced(rig: Rig) -> None:
    rig.host.strategy["r1"] = DIRECT
    rig.host.odometry["r1"] = odom(0.15)
    await rig.tick()
    rig.host.scan_error = ConnectionError("database restarting")
    await rig.tick()  # safety_stop's data acquisition fails: the engine discards the rule
    assert not any(isinstance(r, SafetyStop) for r in rig.engine.current)
    for _ in range(STALL_LIMIT + 2):
        await rig.tick()
    rig.new_scan((-10, 10, 0.14))
    assert await rig.tick() == ["safety_stop"]


def test_the_registry_names_every_builtin_and_refuses_duplicates() -> None:
    assert set(SCENARIOS) >= {"avoid_left", "avoid_right", "safety_stop"}
    assert register(SafetyStop) is SafetyStop  # registering the same class again is harmless

    class Impostor(SafetyStop):
        pass

    with pytest.raises(ValueError, match="already registered"):
        register(Impostor)

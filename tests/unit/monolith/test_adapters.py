"""The monolith's adapters: the in-memory sources, the stepped engines, the strategy rows
from schema.sql, the bridge's watchdog."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from common.contract import keys
from common.contract.recommendations import Recommendation
from common.engine import Rule
from common.planner_core.scenario import RobotInfo
from pnav.bench.nav.stack_episode import Combo
from pnav.monolith.contract import AdapterError, MemoryContract
from pnav.monolith.engines import SteppedEngine
from pnav.monolith.memory_bridge import Applied, Bridge
from pnav.monolith.memory_controller import MemoryControllerSource
from pnav.monolith.memory_decision import MemoryDecisionSource
from pnav.monolith.memory_planner import planner_engine
from pnav.monolith.monolith_stack import MonolithStack
from pnav.monolith.strategies import combo_strategy, shipped_strategies
from services.decision.arbitration import RobotDecision
from services.planner.routes import Target
from services.planner.world_model import RobotState
from services.sim.robot import BURGER
from services.sim.sim import SimConfig
from services.sim.world_spec import load_world


def contract_with_rows() -> tuple[MemoryContract, list[tuple[str, Any, Any]]]:
    contract = MemoryContract()
    notes: list[tuple[str, Any, Any]] = []
    contract.listeners.append(lambda table, robot, row_id: notes.append((table, robot, row_id)))
    for robot in ("r2", "r1"):
        # every model column, as the bridge writes them from the sim's world message
        contract.insert(keys.ROBOT, {"robot_id": robot, **BURGER.robot_row()})
    for i in range(3):
        row = {"robot_id": "r1", "stamp": i / 30, "seq": i, "x": float(i), "y": 0.0, "yaw": 0.0}
        contract.insert(keys.ODOMETRY, row | {"linear_mps": 0.1, "angular_rps": 0.0})
    return contract, notes


async def test_the_controller_source_reads_the_in_memory_rows() -> None:
    contract, _notes = contract_with_rows()
    source = MemoryControllerSource(contract)
    assert [r.robot_id for r in await source.robots()] == ["r1", "r2"]  # ORDER BY robot_id
    odom = await source.newest_odometry("r1")
    assert odom is not None and (odom.id, odom.stamp, odom.x) == (3, 2 / 30, 2.0)
    assert await source.newest_odometry("r3") is None


async def test_a_write_notifies_after_it_and_the_decision_marks_what_it_considered() -> None:
    contract, notes = contract_with_rows()
    rec = await MemoryControllerSource(contract).recommend(
        Recommendation.velocity(
            "r1", source="x", priority=5, linear=0.1, angular=0.0, stamp=1.0, ttl_s=0.5, reason=""
        )
    )
    assert notes[-1] == (keys.COMMAND_RECOMMENDATION, "r1", rec)
    decisions = MemoryDecisionSource(contract)
    live = await decisions.live_recommendations(1.2)
    assert [r.id for r in live["r1"]] == [rec] and live["r2"] == []
    assert (await decisions.live_recommendations(1.5))["r1"] == []  # expired
    decision = RobotDecision("r1", 1.2, 0.1, 0.0, rec, "x", (rec,), "why")
    issued = await decisions.write_robot_command(decision)
    assert contract[keys.COMMAND_RECOMMENDATION].by_id[rec]["treated_by"] == issued
    assert notes[-1] == (keys.COMMAND2ROBOT, "r1", issued)  # after treated_by was set
    assert (await decisions.last_issued())["r1"].recommendation_id == rec


class Broken(Rule):
    scenario = "broken"
    meta = True

    def __init__(self, error: Exception) -> None:
        self.error = error

    def data_acquisition(self) -> None:
        raise self.error


async def test_a_plumbing_failure_stops_the_run_and_a_rule_error_does_not() -> None:
    engine = SteppedEngine("test", lambda: 0.0)
    engine.add_meta(lambda: Broken(AdapterError("the in-memory contract broke")))
    with pytest.raises(AdapterError):
        await engine.activate(0.0)
    engine = SteppedEngine("test", lambda: 0.0)
    engine.add_meta(lambda: Broken(ValueError("the rule's own bug")))
    await engine.activate(0.0)  # logged and discarded, the meta rule re-seeded: as in the stack
    assert engine.errors == 1 and len(engine.current) == 1


async def test_the_engine_is_due_on_a_notification_a_hurry_or_f_of_sim_time() -> None:
    engine = SteppedEngine("test", lambda: 0.0)
    assert engine.due(0.0)  # a service starts with an activation
    await engine.activate(0.0)
    assert not engine.due(0.01)
    assert engine.due(engine.settings.period_s)
    engine.wake()
    assert engine.due(0.01)
    await engine.activate(0.01)
    engine.hurry()
    assert engine.due(0.02)


def test_the_strategy_rows_come_from_schema_sql() -> None:
    shipped = shipped_strategies()
    assert shipped["GOTO_AVOID"].controller_scenarios == (
        "avoid_left",
        "avoid_right",
        "safety_stop",
    )
    assert shipped["GOTO_DIRECT"].controller_scenarios == ("safety_stop",)
    assert shipped["GOTO_AVOID"].params["target"] == "goal"
    assert shipped["IDLE"].planner_scenario is None
    combo = combo_strategy(Combo("GOTO_DIRECT", "move_while_turning"), shipped)
    assert (combo.code, combo.planner_scenario) == (
        "NAV_GOTO_DIRECT_MOVE_WHILE_TURNING",
        "move_while_turning",
    )
    assert combo.params == shipped["GOTO_DIRECT"].params


def test_a_migration_merging_params_into_a_strategy_row_is_followed_and_others_refused() -> None:
    # migration 19 merges dwa_bends_in_open into GOTO_DODGE: the monolith runs it as the stack
    assert shipped_strategies()["GOTO_DODGE"].params["dwa_bends_in_open"] == 0
    assert "dwa_bends_in_open" not in shipped_strategies()["GOTO_FAST"].params
    base = (
        "INSERT INTO strategy (code, params) VALUES ('A', '{\"x\": 1}'), ('B', '{}');\n"
        "UPDATE strategy SET params = params || '{\"x\": 2, \"y\": \"it''s\"}' WHERE code = 'A';\n"
    )
    rows = shipped_strategies(base)
    assert rows["A"].params == {"x": 2, "y": "it's"} and rows["B"].params == {}
    # an insert after the merge is not touched by it: statements apply in order
    later = shipped_strategies(base + "INSERT INTO strategy (code, params) VALUES ('C', '{}');")
    assert later["C"].params == {}
    for change in ("UPDATE strategy SET planner_scenario = NULL;", "DELETE FROM strategy;"):
        with pytest.raises(AdapterError, match="changes strategy rows"):
            shipped_strategies(base + change)


def test_the_planner_counts_its_own_gates_on_the_clock_it_is_given() -> None:
    # the monolith hands the planner sim time for its gates (re-reads, replanning): a route
    # is born at that clock's time, not at the wall clock's
    t = [42.0]
    store = planner_engine(MemoryContract(), SteppedEngine("planner", lambda: t[0]), lambda: t[0])
    robot = RobotState(RobotInfo("r1", None, 0.22, 2.84, 0.105))
    store.route_for(robot, 0.0, 0.0, Target("goal", "1", 1.0, 0.0, 0.15, 0.3), 0.0)
    assert robot.route is not None and robot.route.made_at == 42.0


async def test_the_bridge_clamps_sends_once_and_stops_a_robot_left_without_commands() -> None:
    contract, _notes = contract_with_rows()
    sent: list[tuple[str, float, float]] = []
    applied: list[Applied] = []
    bridge = Bridge(contract, lambda r, v, w: sent.append((r, v, w)) is None, applied.append)
    decision = RobotDecision("r1", 1.0, 5.0, float("nan"), None, None, (), "too fast")
    await MemoryDecisionSource(contract).write_robot_command(decision)
    assert bridge.relay(1.0) == 1 and bridge.relay(1.01) == 0  # each row once
    assert sent == [("r1", 0.22, 0.0)]  # clamped; NaN is 0
    bridge.tick(1.49)
    assert len(sent) == 1
    bridge.tick(1.5)  # 0.5 s of sim time without a fresh command
    assert sent[-1] == ("r1", 0.0, 0.0) and applied[-1].decided_stamp is None
    bridge.tick(2.5)
    assert len(sent) == 2  # the watchdog stops once


async def test_a_row_written_is_noted_by_the_stores_that_watch_its_table_and_wakes_them() -> None:
    world = load_world(Path(__file__).parents[3] / "worlds" / "open_room.yaml")
    stack = MonolithStack(world, SimConfig(), [])
    try:
        for engine in stack.engines:
            await engine.activate(0.0)
        assert not any(e.signals.pending for e in stack.engines)
        stack.contract.insert(keys.GOAL, {"robot_id": "r1", "x": 1.0, "y": 1.0, "status": "active"})
        # the planner watches goals; the controller and the decision do not
        assert [e.name for e in stack.engines if e.signals.woken] == ["planner"]
    finally:
        stack.close()

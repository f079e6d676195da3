"""A strategy the planner cannot run ends with the robot's goal failed and the reason, never
stuck ``active``: a planner scenario not installed here, or controller scenarios no live
controller offers (scenario_offer), tick by tick on the in-memory contract."""

from __future__ import annotations

import logging

import pytest

from common.contract import keys
from tests.unit.planner.harness import ROBOT, Planner

ODD = {"code": "ODD", "planner_scenario": "no_such_scenario", "params": {"target": "goal"}}
# GOTO_FAST's scenarios with a local controller no controller here has
FAST = {
    "code": "FASTER",
    "planner_scenario": "turn_then_move",
    "controller_scenarios": ["warp_drive", "safety_stop"],
    "params": {"target": "goal", "planner_drives": False},
}


def paths(p: Planner) -> list[dict[str, object]]:
    return list(p.contract[keys.PLANNED_PATH].rows(ROBOT))


async def test_an_unknown_planner_scenario_fails_each_goal_with_the_reason_warned_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    p = Planner(extra_strategies=(ODD,))
    p.strategy("ODD")
    first = p.goal(2.0, 0.0)
    with caplog.at_level(logging.WARNING, logger="pnav.planner"):
        for _ in range(4):
            await p.tick()
            assert p.running() == {"move": ("Unrunnable", "ODD")}
        second = p.goal(0.0, 2.0)  # a new goal under the same strategy fails too
        for _ in range(4):
            await p.tick()
    for goal_id in (first, second):
        row = p.goal_row(goal_id)
        assert row["status"] == "failed"
        assert row["reason"] == (
            "strategy ODD names planner scenario 'no_such_scenario' that this planner cannot "
            "run; it runs: turn_then_move, move_while_turning"
        )
    warned = [r for r in caplog.records if r.getMessage().startswith("unknown planner scenario")]
    assert len(warned) == 1
    assert p.recommendations() == []
    # one empty path, so a local controller stops following an old one
    assert [(r["target"], r["xs"]) for r in paths(p)] == [("none", [])]


async def test_a_controller_scenario_no_live_controller_offers_fails_the_goal() -> None:
    p = Planner(extra_strategies=(FAST,))
    p.contract.offer("controller", ["avoid_left", "avoid_right", "dwa", "safety_stop"])
    p.strategy("FASTER")
    goal = p.goal(2.0, 0.0)
    for _ in range(3):
        await p.tick()
    assert p.running() == {"move": ("Unrunnable", "FASTER")}
    row = p.goal_row(goal)
    assert row["status"] == "failed"
    assert row["reason"] == (
        "strategy FASTER names controller scenario 'warp_drive' that no running controller "
        "offers; offered: avoid_left, avoid_right, dwa, safety_stop"
    )


async def test_with_no_controller_offer_heard_the_controller_scenarios_are_not_judged() -> None:
    p = Planner(extra_strategies=(FAST,))  # no controller has published its offers (yet)
    p.strategy("FASTER")
    goal = p.goal(2.0, 0.0)
    for _ in range(3):
        await p.tick()
    assert p.running()["move"] == ("TurnThenMove", "FASTER")
    assert p.goal_row(goal)["status"] == "active"


async def test_a_scenario_offered_again_brings_the_strategy_back() -> None:
    p = Planner(extra_strategies=(FAST,))
    p.contract.offer("controller", ["safety_stop"])
    p.strategy("FASTER")
    await p.tick()
    assert p.running() == {"move": ("Unrunnable", "FASTER")}
    # a controller with the plug-in is back (announced: the store reads the offers again)
    p.contract.offer("controller", ["warp_drive"])
    await p.tick()
    assert p.running()["move"] == ("TurnThenMove", "FASTER")
    goal = p.goal(2.0, 0.0)
    for _ in range(3):
        await p.tick()
    assert p.goal_row(goal)["status"] == "active"

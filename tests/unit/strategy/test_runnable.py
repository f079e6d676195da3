"""Whether a strategy can run now (services/strategy/runnable.py) and the decision table
with it: every command that would switch the robot to a strategy naming a scenario no live
planner or controller offers is rejected with the reason; a family with no live offer is not
judged; the monolith's in-memory source judges as Postgres does."""

from __future__ import annotations

import pytest

from common.contract import keys
from common.contract.offers import Offers
from common.engine import Engine
from pnav.monolith.contract import MemoryContract
from pnav.monolith.memory_strategy import strategy_engine, user_command
from services.strategy.commands import RobotState, decide
from services.strategy.runnable import Needs, refusal

NEEDS = {
    "GOTO_AVOID": Needs("turn_then_move", ("avoid_left", "avoid_right", "safety_stop")),
    "CHARGE": Needs("turn_then_move", ("avoid_left", "avoid_right", "safety_stop")),
    "WARP": Needs("turn_then_move", ("warp_drive", "hyper", "safety_stop")),
    "ODD": Needs("teleport", ()),
    "IDLE": Needs(None, ()),
}
OFFERS = Offers.of(
    [("planner", "turn_then_move"), ("controller", "safety_stop"), ("controller", "avoid_left")]
)


def test_a_strategy_everything_of_which_is_offered_can_run() -> None:
    assert refusal("IDLE", NEEDS, OFFERS) is None
    assert refusal("NOT_A_ROW", NEEDS, OFFERS) is None  # the decision table says unknown


def test_each_missing_scenario_is_named_with_what_is_offered() -> None:
    assert refusal("WARP", NEEDS, OFFERS) == (
        "strategy WARP names controller scenarios 'warp_drive', 'hyper' that no running "
        "controller offers; offered: avoid_left, safety_stop"
    )
    assert refusal("ODD", NEEDS, OFFERS) == (
        "strategy ODD names planner scenario 'teleport' that no running planner offers; "
        "offered: turn_then_move"
    )


def test_a_family_with_no_live_offer_is_not_judged() -> None:
    planners_only = Offers.of([("planner", "turn_then_move")])
    assert refusal("WARP", NEEDS, planners_only) is None
    assert refusal("ODD", NEEDS, Offers()) is None


@pytest.mark.parametrize(
    ("command", "argument", "state", "strategy"),
    [
        ("SET_STRATEGY", "warp", RobotState(True, "GOTO_AVOID", None), "WARP"),
        ("CMD_BATTSAVE", None, RobotState(True, "GOTO_AVOID", None), "CHARGE"),
        ("CMD_RESUME", None, RobotState(True, "CHARGE", "WARP"), "WARP"),
    ],
)
def test_every_switch_to_a_strategy_that_cannot_run_is_rejected_with_why(
    command: str, argument: str | None, state: RobotState, strategy: str
) -> None:
    def judge(code: str) -> str | None:
        return f"{code} cannot run" if code == strategy else None

    codes = set(NEEDS)
    assert decide(command, argument, state, codes).accepted  # as before, unjudged
    outcome = decide(command, argument, state, codes, judge)
    assert not outcome.accepted and outcome.reason == f"{strategy} cannot run"


def test_an_unknown_code_is_still_refused_as_unknown_before_anything_is_judged() -> None:
    outcome = decide(
        "SET_STRATEGY", "nope", RobotState(True, "GOTO_AVOID", None), set(NEEDS), lambda c: "x"
    )
    assert outcome.reason.startswith("unknown strategy 'NOPE'")


async def test_the_monolith_source_judges_a_switch_on_its_services_offers() -> None:
    contract = MemoryContract()
    for code, need in NEEDS.items():
        row = {"code": code, "planner_scenario": need.planner}
        contract.insert(keys.STRATEGY, row | {"controller_scenarios": list(need.controller)})
    contract.insert(keys.ROBOT, {"robot_id": "r1"})
    contract.offer("planner", ["turn_then_move"])
    contract.offer("controller", ["avoid_left", "avoid_right", "safety_stop"])
    engine = Engine(name="strategy")
    strategy_engine(contract, engine, lambda: 1.0)
    await engine.activation()  # the default strategy is scheduled
    await engine.activation()  # and given
    warp = user_command(contract, "r1", "SET_STRATEGY", "WARP")
    for _ in range(3):
        await engine.activation()
    row = contract[keys.USER_COMMAND].by_id[warp]
    assert (row["status"], row["reason"]) == (
        "rejected",
        "strategy WARP names controller scenarios 'warp_drive', 'hyper' that no running "
        "controller offers; offered: avoid_left, avoid_right, safety_stop",
    )
    active = contract[keys.ACTIVE_STRATEGY].newest("r1")
    assert active is not None and active["strategy_code"] == "GOTO_AVOID"  # unchanged

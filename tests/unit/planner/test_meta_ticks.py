"""The meta-planner, tick by tick (as py_trees tests a tree): one engine activation per step,
on the in-memory contract with the real store, the state expected after it beside it.

``running``: kind -> (rule, strategy) of the robot's live target rules (the supervisor's
behaviours); ``queue``: the rules the next activation runs, in order."""

from __future__ import annotations

from typing import Any

from common.planner_core.scenario import Movement, MoveScenario, RobotInfo
from services.planner import meta
from services.planner.routes import Target
from tests.unit.planner.harness import ROBOT, Planner

GOTO = {"move": ("TurnThenMove", "GOTO_AVOID"), "battery": ("BatteryCheck", "GOTO_AVOID")}
CHARGE = {"move": ("TurnThenMove", "CHARGE"), "battery": ("ChargeComplete", "CHARGE")}


async def test_a_strategy_switch_replaces_the_rules_in_one_activation_and_idle_ends_them() -> None:
    p = Planner()
    p.strategy("GOTO_AVOID")
    p.goal(0.0, 2.0)  # to the left

    await p.tick()  # the meta-planner reads the world and the strategy: both rules start
    assert p.running() == GOTO
    assert p.queue() == ["TurnThenMove", "BatteryCheck", "MetaPlanner"]
    assert p.recommendations() == []

    await p.tick()  # the move rule turns toward the goal; the battery is full enough
    assert p.running() == GOTO
    assert p.queue() == ["TurnThenMove", "BatteryCheck", "MetaPlanner"]
    turns = p.recommendations("turn_then_move")
    assert len(turns) == 1 and turns[0]["angular_rps"] > 0 and turns[0]["linear_mps"] == 0.0
    assert turns[0]["inputs"]["strategy"] == "GOTO_AVOID"
    old_move, old_battery = p.live_rule("move"), p.live_rule("battery")

    p.strategy("CHARGE")
    await p.tick()  # the old rules run first (still wanted), then the meta-planner swaps them
    assert p.running() == CHARGE
    assert not old_move.live and not old_battery.live  # ended: they will not queue again
    assert p.queue() == [
        "TurnThenMove",  # the old rule, queued before the switch: it will not act
        "BatteryCheck",
        "TurnThenMove",  # the new ones, started in the same activation
        "ChargeComplete",
        "MetaPlanner",
    ]
    said = len(p.recommendations())

    await p.tick()  # the old rules find they ended: no action, not queued again
    assert p.running() == CHARGE
    assert p.queue() == ["TurnThenMove", "ChargeComplete", "MetaPlanner"]
    new = p.recommendations()[said:]
    # the system recommendation is written when its rule asks; the velocity at the
    # activation's end (the store holds velocities for one write: services/planner/store.py)
    assert [(r["source"], r["inputs"].get("charger")) for r in new] == [
        ("charge_complete", None),  # 75 % holds 3x what the way back to the goal needs
        ("turn_then_move", "dock"),  # the new move rule drives to the charger
    ]
    assert new[1]["inputs"]["strategy"] == "CHARGE" and new[0]["system_command"] == "CMD_RESUME"

    p.strategy("IDLE")
    await p.tick()  # IDLE has no planner scenario: both rules end
    assert p.running() == {}
    assert p.queue() == ["TurnThenMove", "ChargeComplete", "MetaPlanner"]
    said = len(p.recommendations())

    await p.tick()
    assert p.running() == {}
    assert p.queue() == ["MetaPlanner"]
    assert len(p.recommendations()) == said  # nothing more from the ended rules


class Stumbling(MoveScenario):
    """Drives straight ahead; its first run fails (a bug the engine must survive)."""

    scenario = "stumbling"
    failures = 1

    def select(
        self, error: float, remaining_m: float, info: RobotInfo, turn_rate: float = 0.0
    ) -> Movement:
        if Stumbling.failures:
            Stumbling.failures -= 1
            raise RuntimeError("stumbled")
        return Movement(0.1, 0.0, False)


STUMBLE: dict[str, Any] = {
    "code": "STUMBLE",
    "planner_scenario": "stumbling",
    "params": {"target": "goal"},
}


async def test_a_target_rule_discarded_on_an_error_starts_again_at_the_next_meta_run() -> None:
    p = Planner({"stumbling": Stumbling}, (STUMBLE,))
    p.strategy("STUMBLE")
    p.goal(2.0, 0.0)

    await p.tick()  # started
    assert p.running() == {"move": ("Stumbling", "STUMBLE"), "battery": ("BatteryCheck", "STUMBLE")}
    first = p.live_rule("move")

    await p.tick()  # the rule raises and is discarded; the meta-planner runs after it
    assert first.lost
    assert p.rules.supervisor.restarted == 1
    assert p.live_rule("move") is not first
    assert p.queue() == ["BatteryCheck", "Stumbling", "MetaPlanner"]
    assert p.recommendations("stumbling") == []

    await p.tick()  # the new rule drives
    assert [r["linear_mps"] for r in p.recommendations("stumbling")] == [0.1]
    assert p.rules.supervisor.restarted == 1
    assert p.queue() == ["BatteryCheck", "Stumbling", "MetaPlanner"]


async def test_a_robot_another_replica_takes_over_ends_its_rules_here() -> None:
    p = Planner()
    p.strategy("GOTO_AVOID")
    p.goal(2.0, 0.0)
    await p.tick()
    await p.tick()
    assert p.running() == GOTO
    said = len(p.recommendations())

    p.owned.discard(ROBOT)  # the lease went to another replica
    await p.tick()  # the rules ran once more before the meta-planner ended them
    assert p.running() == {}
    assert p.queue() == ["TurnThenMove", "BatteryCheck", "MetaPlanner"]
    await p.tick()
    assert p.queue() == ["MetaPlanner"]
    acted = len(p.recommendations()) - said
    await p.tick()
    assert len(p.recommendations()) - said == acted  # nothing for the robot any more

    p.owned.add(ROBOT)  # and back: the rules start afresh
    await p.tick()
    assert p.running() == GOTO


async def test_forgetting_a_robot_ends_its_rules_before_they_run_again() -> None:
    # what the service does on an ownership change: no run of the old rules after it
    p = Planner()
    p.strategy("GOTO_AVOID")
    p.goal(0.0, 2.0)
    await p.tick()
    await p.tick()
    old = p.live_rule("move")
    p.store.forget({ROBOT})
    p.rules.forget({ROBOT})
    assert p.running() == {} and not old.live
    said = len(p.recommendations())
    await p.tick()  # the old rules stop; the meta-planner starts new ones (still owned)
    assert p.running() == GOTO and p.live_rule("move") is not old
    assert len(p.recommendations()) == said


def test_the_shipped_scenarios_come_from_the_entry_points_the_planners_own_first() -> None:
    found = meta.move_scenarios()
    assert list(found)[:2] == ["turn_then_move", "move_while_turning"]
    assert all(issubclass(cls, MoveScenario) for cls in found.values())


def looks(rule: MoveScenario) -> tuple[Any, ...]:
    """What a move rule's guards or conditions could change: its own findings and memory,
    and the robot's route."""
    robot = rule.robot
    route = robot.route if robot is not None else None
    mine = (rule.news, rule.worth_saying, rule.last_said, rule.arrived, rule.move, rule.why)
    memory = (set(rule.held), rule.said, rule.turning)
    track = (route, route.segment, route.checked_scan) if route is not None else None
    return mine, memory, track


async def test_guards_and_conditions_only_look() -> None:
    p = Planner()
    p.strategy("GOTO_AVOID")
    p.goal(2.0, 0.0)
    await p.tick()
    await p.tick()
    rule = p.live_rule("move")
    assert isinstance(rule, MoveScenario)
    p.sense(0.1)  # a new odometry row, due a recommendation
    await rule.data_acquisition()
    assert isinstance(rule.target, Target) and rule.news and rule.worth_saying
    acquired = looks(rule)
    for _ in range(3):
        assert all(rule.activation_guards()) and all(rule.conditions())
        assert looks(rule) == acquired

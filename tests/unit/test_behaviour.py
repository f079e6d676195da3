"""A long-lived target rule (common.engine.Behaviour), activation by activation.

Each step names what the meta rule wants (robot -> strategy), then, beside it, the state
expected after the engine's activation: the hooks and runs logged, the object in the queue.
"""

from __future__ import annotations

from collections.abc import Iterable

import pytest

from common.config import EngineSettings
from common.engine import Behaviour, Engine, Rule, Supervisor
from common.engine.steps import StepRunner

Key = tuple[str, str]  # (robot, kind)


class Follow(Behaviour[Key, str]):
    """Counts its own runs in ``self`` (no clone may lose them); logs its hooks."""

    scenario = "follow"

    def __init__(self, key: Key, spec: str, log: list[str]) -> None:
        super().__init__(key, spec)
        self.robot_id = key[0]
        self.log = log
        self.runs = 0

    def initialise(self) -> None:
        self.log.append(f"initialise {self.robot_id} {self.spec}")

    def terminate(self, why: str) -> None:
        self.log.append(f"terminate {self.robot_id} {self.spec}: {why}")

    def activation_guards(self) -> bool:
        return self.live

    def actions(self) -> None:
        self.runs += 1
        self.log.append(f"update {self.robot_id} {self.spec} #{self.runs}")


class Meta(Rule):
    scenario = "meta_follow"
    meta = True

    def __init__(self, supervisor: Supervisor[Key, str], wanted: dict[str, str]) -> None:
        self.supervisor, self.wanted = supervisor, wanted
        self.started: list[Rule] = []

    def actions(self) -> None:
        want = {(robot, "move"): strategy for robot, strategy in self.wanted.items()}
        self.started = self.supervisor.reconcile(want)

    def rule_generation(self) -> Iterable[Rule]:
        return [self.clone(), *self.started]


class Rig:
    def __init__(self) -> None:
        self.log: list[str] = []
        self.wanted: dict[str, str] = {}
        # a new strategy is a new rule (as in the planner): the old one terminates first
        self.supervisor: Supervisor[Key, str] = Supervisor(
            "follow", lambda k, s: Follow(k, s, self.log), restart_on=lambda old, new: True
        )
        self.engine = Engine(EngineSettings(period_s=10.0))
        self.engine.add_meta(lambda: Meta(self.supervisor, self.wanted))

    async def tick(self) -> list[str]:
        self.log.clear()
        await self.engine.activation()
        return list(self.log)

    def rule(self, robot: str) -> Follow:
        rule = self.supervisor.rule((robot, "move"))
        assert isinstance(rule, Follow)
        return rule

    def queued(self) -> list[Rule]:
        return list(self.engine.current)


async def test_initialise_once_update_on_the_same_object_terminate_on_a_strategy_change() -> None:
    rig = Rig()
    rig.wanted["r1"] = "GOTO"
    assert await rig.tick() == ["initialise r1 GOTO"]  # started; queued for the next one
    first = rig.rule("r1")
    assert first.live and first.runs == 0

    assert await rig.tick() == ["update r1 GOTO #1"]
    assert rig.queued()[-1] is first  # the same object back in the queue, no clone
    assert await rig.tick() == ["update r1 GOTO #2"]  # its state lives in self
    assert rig.queued()[-1] is first and first.runs == 2
    assert rig.supervisor.started == 1  # initialised once

    rig.wanted["r1"] = "CHARGE"
    # the meta rule runs first: GOTO ends, CHARGE starts; GOTO's queued run does nothing
    assert await rig.tick() == [
        "terminate r1 GOTO: no longer wanted",
        "initialise r1 CHARGE",
    ]
    second = rig.rule("r1")
    assert second is not first and not first.live and first.runs == 2
    assert first not in rig.queued() and second in rig.queued()
    assert await rig.tick() == ["update r1 CHARGE #1"]
    assert (rig.supervisor.started, rig.supervisor.ended) == (2, 1)


async def test_a_robot_gone_terminates_its_behaviour() -> None:
    rig = Rig()
    rig.wanted.update(r1="GOTO", r2="GOTO")
    assert await rig.tick() == ["initialise r1 GOTO", "initialise r2 GOTO"]
    assert await rig.tick() == ["update r1 GOTO #1", "update r2 GOTO #1"]
    gone = rig.rule("r2")

    del rig.wanted["r2"]  # the robot left
    assert await rig.tick() == ["terminate r2 GOTO: no longer wanted", "update r1 GOTO #2"]
    assert not gone.live and gone.runs == 1  # ran once more, did nothing
    assert await rig.tick() == ["update r1 GOTO #3"]  # and left the queue
    assert gone not in rig.queued() and sorted(rig.supervisor.running) == [("r1", "move")]


async def test_close_terminates_what_still_runs_when_the_service_stops() -> None:
    rig = Rig()
    rig.wanted.update(r1="GOTO", r2="CHARGE")
    assert await rig.tick() == ["initialise r1 GOTO", "initialise r2 CHARGE"]
    assert await rig.tick() == ["update r1 GOTO #1", "update r2 CHARGE #1"]

    rig.log.clear()
    assert rig.engine.close() == 2
    assert rig.log == [
        "terminate r1 GOTO: the service stopped",
        "terminate r2 CHARGE: the service stopped",
    ]
    assert rig.engine.close() == 0 and len(rig.log) == 2  # once only
    assert await rig.tick() == []  # were the engine run again: they act no more


async def test_a_lost_behaviour_is_replaced_and_may_resume_from_it() -> None:
    rig = Rig()
    rig.wanted["r1"] = "GOTO"
    await rig.tick()
    await rig.tick()
    first = rig.rule("r1")
    first.discarded("actions")  # what the engine tells a rule it discarded on an error
    assert first.lost
    rig.engine.current.remove(first)  # as the engine does: not queued again

    assert await rig.tick() == [
        "terminate r1 GOTO: its rule was discarded after an error",
        "initialise r1 GOTO",
    ]
    assert rig.rule("r1") is not first and rig.supervisor.restarted == 1


class Plumbing(Exception):
    """Stands for the monolith's own failures (its AdapterError)."""


class Broken(Rule):
    def __init__(self, error: Exception) -> None:
        self.error = error

    def actions(self) -> None:
        raise self.error


async def test_the_steps_are_the_engines_collaborator_and_fatal_errors_stop_it() -> None:
    engine = Engine(EngineSettings(period_s=10.0), fatal=(Plumbing,))
    assert isinstance(engine.steps, StepRunner) and not isinstance(engine, StepRunner)

    engine.add(Broken(RuntimeError("a rule's own error")))
    assert await engine.activation() == 1  # discarded, counted, the engine runs on
    assert engine.stats_for(Broken).errors == 1

    engine.add(Broken(Plumbing("the adapter failed")))
    with pytest.raises(Plumbing):
        await engine.activation()
    assert engine.stats_for(Broken).errors == 1  # not counted as a rule's error

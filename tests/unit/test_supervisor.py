"""The scenario supervisor, tick by tick: what a meta rule wants is what runs.

Each step names what the meta rule wants, then the state expected after the engine's
activation, as py_trees' tests do.
"""

from __future__ import annotations

from collections.abc import Iterable

from common.config import EngineSettings
from common.engine import Behaviour, Engine, Rule, Supervisor

Key = tuple[str, str]


class Probe(Behaviour[Key, str]):
    """A target rule that logs its runs and hooks; fails when its spec says so."""

    scenario = "probe"

    def __init__(self, key: Key, spec: str, log: list[str]) -> None:
        super().__init__(key, spec)
        self.log = log
        self.memory: dict[str, int] = {}

    def initialise(self) -> None:
        self.log.append(f"init {self.key[1]}")

    def terminate(self, why: str) -> None:
        self.log.append(f"end {self.key[1]}: {why}")

    def resume(self, lost: Behaviour[Key, str]) -> None:
        if isinstance(lost, Probe):
            self.memory = lost.memory

    def activation_guards(self) -> bool:
        return self.live  # an ended scenario's last queued rule does nothing

    def actions(self) -> None:
        self.log.append(f"run {self.key[1]}:{self.spec}")
        self.memory["runs"] = self.memory.get("runs", 0) + 1
        if self.spec == "fail":
            raise RuntimeError("planned failure")


class Meta(Rule):
    scenario = "meta_probe"
    meta = True

    def __init__(self, supervisor: Supervisor[Key, str], wanted: dict[Key, str]) -> None:
        self.supervisor, self.wanted = supervisor, wanted
        self.started: list[Rule] = []

    def actions(self) -> None:
        self.started = self.supervisor.reconcile(dict(self.wanted))

    def rule_generation(self) -> Iterable[Rule]:
        return [self.clone(), *self.started]


def setup() -> tuple[Engine, Supervisor[Key, str], dict[Key, str], list[str]]:
    log: list[str] = []
    wanted: dict[Key, str] = {}
    supervisor: Supervisor[Key, str] = Supervisor("probe", lambda k, s: Probe(k, s, log))
    engine = Engine(EngineSettings(period_s=10.0))
    engine.add_meta(lambda: Meta(supervisor, wanted))
    return engine, supervisor, wanted, log


async def tick(engine: Engine, log: list[str]) -> list[str]:
    log.clear()
    await engine.activation()
    return list(log)


async def test_scenarios_start_update_end_and_restart_as_wanted() -> None:
    engine, sup, wanted, log = setup()

    wanted[("r1", "a")] = "v1"
    assert await tick(engine, log) == ["init a"]  # meta starts a; it runs next activation
    assert await tick(engine, log) == ["run a:v1"]  # a runs, clones itself

    wanted[("r1", "a")] = "v2"
    assert await tick(engine, log) == ["run a:v2"]  # updated in place: no end, no init
    assert sup.started == 1 and sup.ended == 0

    wanted[("r1", "b")] = "fail"
    assert await tick(engine, log) == ["init b", "run a:v2"]  # the meta rule runs first
    assert await tick(engine, log) == ["run b:fail", "run a:v2"]  # b raises: discarded
    rule_b = sup.rule(("r1", "b"))
    assert rule_b is not None and rule_b.lost

    wanted[("r1", "b")] = "ok"  # restarted at the next reconcile, its memory carried over
    assert await tick(engine, log) == [
        "end b: its rule was discarded after an error",
        "init b",
        "run a:v2",
    ]
    restarted = sup.rule(("r1", "b"))
    assert isinstance(restarted, Probe)
    assert restarted.memory == {"runs": 1} and sup.restarted == 1
    assert await tick(engine, log) == ["run b:ok", "run a:v2"]

    del wanted[("r1", "a")]
    # a's queued rule sees it ended: does nothing, does not queue itself again
    assert await tick(engine, log) == ["end a: no longer wanted", "run b:ok"]
    assert await tick(engine, log) == ["run b:ok"]  # a queued itself no more
    assert sorted(sup.running) == [("r1", "b")]
    assert len(engine) == 2  # the meta rule and b


async def test_restart_on_replaces_the_rule_without_overlap() -> None:
    log: list[str] = []
    wanted: dict[Key, str] = {("r1", "move"): "turn"}
    sup: Supervisor[Key, str] = Supervisor(
        "probe", lambda k, s: Probe(k, s, log), restart_on=lambda old, new: old != new
    )
    engine = Engine(EngineSettings(period_s=10.0))
    engine.add_meta(lambda: Meta(sup, wanted))
    assert await tick(engine, log) == ["init move"]
    assert await tick(engine, log) == ["run move:turn"]
    wanted[("r1", "move")] = "curve"
    # the old rule, still queued, sees it ended (no run, not queued again); the new rule
    # runs from the next activation
    assert await tick(engine, log) == ["end move: no longer wanted", "init move"]
    assert await tick(engine, log) == ["run move:curve"]
    assert await tick(engine, log) == ["run move:curve"]

"""Queue invariants of the engine, checked with hypothesis against a reference model.

The model is the thesis' algorithm written as plainly as possible: two lists, N per
activation, ``next`` appended to ``current`` after each activation. For any program of rules
(random fan-out, guards, failures) and any N, the engine must run exactly the rules the model
runs, in the same order, each at most once, and lose none.

Rules belong to robot r1, r2 or none; the second test runs focused activations too
(docs/ENGINE.md, "Per-robot wake-ups"): the model passes over the rules of robots out of
focus, leaving them in their place, and counts only the rules that ran towards N.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import uvloop
from hypothesis import given, settings
from hypothesis import strategies as st

from common.config import EngineSettings
from common.engine import Engine, Rule


@dataclass
class Spec:
    """One rule of a generated program."""

    guard: bool
    fails: bool
    children: list[Spec] = field(default_factory=list)
    robot: str | None = None


robots = st.sampled_from([None, "r1", "r2"])
specs = st.recursive(
    st.builds(Spec, st.booleans(), st.booleans(), robot=robots),
    lambda inner: st.builds(
        Spec, st.booleans(), st.booleans(), st.lists(inner, max_size=3), robot=robots
    ),
    max_leaves=20,
)
focuses = st.lists(
    st.sampled_from([None, frozenset({"r1"}), frozenset({"r2"}), frozenset({"r1", "r2"})]),
    max_size=8,
)


class Node(Rule):
    def __init__(self, spec: Spec, ident: str, log: list[str]) -> None:
        self.spec, self.ident, self.log = spec, ident, log
        self.robot_id = spec.robot

    def activation_guards(self) -> bool:
        return self.spec.guard

    def actions(self) -> None:
        if self.spec.fails:
            raise RuntimeError("planned failure")

    def data_acquisition(self) -> None:
        self.log.append(self.ident)

    def rule_generation(self) -> list[Rule]:
        return [
            Node(child, f"{self.ident}.{i}", self.log) for i, child in enumerate(self.spec.children)
        ]


def model(roots: list[Spec], n: int, activations: int) -> list[str]:
    """The thesis' algorithm, plainly."""
    current = [(spec, str(i)) for i, spec in enumerate(roots)]
    nxt: list[tuple[Spec, str]] = []
    order = []
    for _ in range(activations):
        ran = 0
        while current and ran < n:
            spec, ident = current.pop(0)
            order.append(ident)
            ran += 1
            if spec.guard and spec.fails:
                continue  # error in actions: discarded, no generation
            nxt.extend((c, f"{ident}.{i}") for i, c in enumerate(spec.children))
        current.extend(nxt)
        nxt = []
    return order


@settings(max_examples=150, deadline=None)
@given(roots=st.lists(specs, min_size=1, max_size=6), n=st.integers(1, 8))
def test_no_rule_is_lost_or_run_twice_and_order_matches_the_model(
    roots: list[Spec], n: int
) -> None:
    log: list[str] = []
    engine = Engine(EngineSettings(period_s=60.0, max_rules=n))
    for i, spec in enumerate(roots):
        engine.add(Node(spec, str(i), log))

    async def drive() -> int:
        activations = 0
        while len(engine):
            await engine.activation()
            activations += 1
        return activations

    activations = uvloop.run(drive())
    assert len(log) == len(set(log)), "a rule ran twice"
    assert log == model(roots, n, activations), "the engine's order differs from the model"
    assert engine.counters.rules_run == len(log)


def focused_model(
    roots: list[Spec], n: int, focus_of: list[frozenset[str] | None]
) -> tuple[list[str], int]:
    """The thesis' algorithm with focus: activation i is focused on ``focus_of[i]`` (None,
    or past the list's end: full). Returns the order and the number of activations."""
    current = [(spec, str(i)) for i, spec in enumerate(roots)]
    order = []
    activation = 0
    while current:
        focus = focus_of[activation] if activation < len(focus_of) else None
        passed: list[tuple[Spec, str]] = []
        nxt: list[tuple[Spec, str]] = []
        ran = 0
        while current:
            spec, ident = current[0]
            if focus is not None and spec.robot is not None and spec.robot not in focus:
                passed.append(current.pop(0))  # keeps its place, not counted
                continue
            if ran >= n:
                break
            current.pop(0)
            order.append(ident)
            ran += 1
            if spec.guard and spec.fails:
                continue
            nxt.extend((c, f"{ident}.{i}") for i, c in enumerate(spec.children))
        current = passed + current + nxt
        activation += 1
    return order, activation


@settings(max_examples=150, deadline=None)
@given(roots=st.lists(specs, min_size=1, max_size=6), n=st.integers(1, 8), focus_of=focuses)
def test_focused_activations_pass_over_other_robots_rules_and_lose_none(
    roots: list[Spec], n: int, focus_of: list[frozenset[str] | None]
) -> None:
    log: list[str] = []
    engine = Engine(EngineSettings(period_s=60.0, max_rules=n))
    for i, spec in enumerate(roots):
        engine.add(Node(spec, str(i), log))

    async def drive() -> int:
        activations = 0
        while len(engine):
            focus = focus_of[activations] if activations < len(focus_of) else None
            await engine.activation(focus)
            activations += 1
        return activations

    activations = uvloop.run(drive())
    order, expected = focused_model(roots, n, focus_of)
    assert len(log) == len(set(log)), "a rule ran twice"
    assert (log, activations) == (order, expected), "the engine's order differs from the model"
    c = engine.counters
    assert c.rules_run == len(log) and c.activations == c.full_activations + c.focused_activations

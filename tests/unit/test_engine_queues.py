"""Queue invariants of the engine, checked with hypothesis against a reference model.

The model is the thesis' algorithm written as plainly as possible: two lists, N per
activation, ``next`` appended to ``current`` after each activation. For any program of rules
(random fan-out, guards, failures) and any N, the engine must run exactly the rules the model
runs, in the same order, each at most once, and lose none.
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


specs = st.recursive(
    st.builds(Spec, st.booleans(), st.booleans()),
    lambda inner: st.builds(Spec, st.booleans(), st.booleans(), st.lists(inner, max_size=3)),
    max_leaves=20,
)


class Node(Rule):
    def __init__(self, spec: Spec, ident: str, log: list[str]) -> None:
        self.spec, self.ident, self.log = spec, ident, log

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

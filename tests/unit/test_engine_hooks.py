"""Activation-end hooks (``Engine.at_activation_end``): awaited after an activation's last
rule, before it counts as ended, in every kind of activation; a failing one is counted and
logged once, and the engine runs on."""

from __future__ import annotations

import asyncio
import logging

import pytest

from common.engine import Rule
from tests.unit.test_engine import Probe, engine


async def test_a_hook_runs_after_the_last_rule_and_before_the_activation_ends() -> None:
    e = engine()
    journal: list[str] = []
    under_way: list[bool] = []

    async def flush() -> None:
        await asyncio.sleep(0)  # a write in flight
        journal.append("flush")
        under_way.append(e.under_way() is not None)

    e.at_activation_end(flush)
    e.add(Probe("a", journal))
    e.add(Probe("b", journal))
    await e.activation()
    # a, b ran their steps; then the hook, with the activation still under way
    assert journal[-1] == "flush" and journal.count("flush") == 1
    assert journal.index("b:act") < journal.index("flush")
    assert under_way == [True]
    assert e.under_way() is None  # ended once the hook returned
    await e.activation()  # an activation with no rule left: the hook still runs
    assert journal.count("flush") == 2


async def test_hooks_run_in_the_order_added_in_focused_activations_too() -> None:
    e = engine()
    journal: list[str] = []

    async def first() -> None:
        journal.append("first")

    async def second() -> None:
        journal.append("second")

    e.at_activation_end(first)
    e.at_activation_end(second)
    r1, r2 = Probe("r1", journal), Probe("r2", journal)
    r1.robot_id, r2.robot_id = "r1", "r2"
    e.add(r1)
    e.add(r2)
    await e.activation(frozenset({"r2"}))  # focused on r2: r1 keeps its place
    assert [entry for entry in journal if ":" not in entry or entry.endswith(":acquire")] == [
        "r2:acquire",
        "first",
        "second",
    ]
    assert len(e.current) == 1  # r1, not run


async def test_a_failing_hook_is_counted_logged_once_and_the_engine_runs_on(
    caplog: pytest.LogCaptureFixture,
) -> None:
    e = engine()
    journal: list[str] = []

    async def broken() -> None:
        raise ConnectionError("database away")

    async def after() -> None:
        journal.append("after")

    e.at_activation_end(broken)
    e.at_activation_end(after)

    class Meta(Rule):
        meta = True

        def actions(self) -> None:
            journal.append("meta")

        def rule_generation(self) -> list[Rule]:
            return [self.clone()]

    e.add_meta(Meta)
    with caplog.at_level(logging.ERROR, logger="pnav.engine"):
        await e.activation()  # 1: the hook fails, the next hook and the rules are unharmed
        await e.activation()  # 2: the same error: counted, not logged again
    assert journal == ["meta", "after", "meta", "after"]
    assert e.counters.hook_errors == 2
    logged = [r for r in caplog.records if "activation-end hook" in r.getMessage()]
    assert len(logged) == 1 and "database away" in logged[0].getMessage()
    assert e.under_way() is None

"""Per-robot wake-ups (docs/ENGINE.md, "Per-robot wake-ups"), activation by activation.

Two robots' continuous rules and a meta rule. ``tick`` does what ``Engine.run`` does once its
trigger returns (take the flags, decide the focus, run the activation) on a clock the test
moves by hand; beside each step: what ran, and the queue after it.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Iterator

import pytest

from common import bus
from common.config import EngineSettings, ZenohSettings
from common.contract import keys
from common.engine import Engine, Rule
from common.lockstep import Ledger, LockstepTrigger
from pnav._testing import eventually


class Bot(Rule):
    """One robot's continuous rule (like a controller scenario): runs, then clones itself.
    ``spawn`` rules are generated once, on its first run; ``hurry`` is called with it."""

    scenario = "bot"

    def __init__(
        self,
        tag: str,
        robot: str | None,
        journal: list[str],
        *,
        spawn: tuple[Rule, ...] = (),
        engine: Engine | None = None,
        hurry: str | None = None,
    ) -> None:
        self.tag, self.robot_id, self.journal = tag, robot, journal
        self.spawn, self.engine, self.hurry_for = spawn, engine, hurry

    def actions(self) -> None:
        self.journal.append(self.tag)
        if self.spawn and self.engine is not None:
            self.engine.hurry(self.hurry_for)

    def rule_generation(self) -> list[Rule]:
        spawned, self.spawn = self.spawn, ()
        twin = self.clone()
        return [*spawned, twin]


class Once(Bot):
    """A target rule: runs once, no clone."""

    def rule_generation(self) -> list[Rule]:
        return []


class Meta(Bot):
    meta = True


def queue(e: Engine) -> list[str]:
    return [r.tag for r in e.current]  # type: ignore[attr-defined]


class Fixture:
    """An engine with F = 50 ms on a hand-moved clock, seeded: meta, a1 (r1), a2 (r2), b1."""

    def __init__(self, max_rules: int = 100, seed: bool = True) -> None:
        self.now = 0.0
        self.journal: list[str] = []
        self.e = Engine(EngineSettings(period_s=0.05, max_rules=max_rules), clock=lambda: self.now)
        if seed:
            self.e.add_meta(lambda: Meta("meta", None, self.journal))
            for tag, robot in (("a1", "r1"), ("a2", "r2"), ("b1", "r1")):
                self.e.add(Bot(tag, robot, self.journal))
        self.first = True

    async def tick(self, at: float) -> list[str]:
        """One activation at time ``at``, as ``Engine.run`` starts it; the rules that ran."""
        self.now = at
        self.journal.clear()
        self.e.signals.take()
        await self.e.activation(self.e.focus(self.first))
        self.first = False
        return list(self.journal)


async def test_a_wake_for_one_robot_runs_the_meta_rule_and_that_robots_rules_only() -> None:
    f = Fixture()
    e = f.e
    assert queue(e) == ["meta", "a1", "a2", "b1"]
    assert await f.tick(0.0) == ["meta", "a1", "a2", "b1"]  # the first one is full
    assert queue(e) == ["meta", "a1", "a2", "b1"]
    e.wake("r1")
    assert await f.tick(0.01) == ["meta", "a1", "b1"]  # focused on r1
    assert queue(e) == ["a2", "meta", "a1", "b1"]  # a2 kept its place, ahead of the clones
    e.wake("r1")
    assert await f.tick(0.02) == ["meta", "a1", "b1"]
    assert queue(e) == ["a2", "meta", "a1", "b1"]  # still first: it runs first when it runs
    e.wake(None)  # a robot-less notification: anything may have changed
    assert await f.tick(0.03) == ["a2", "meta", "a1", "b1"]  # full
    assert queue(e) == ["a2", "meta", "a1", "b1"]
    e.wake("r1")
    e.wake("r2")
    assert await f.tick(0.04) == ["a2", "meta", "a1", "b1"]  # focused on both: all run
    c = e.counters
    assert (c.activations, c.full_activations, c.focused_activations) == (5, 2, 3)
    assert c.out_of_focus == 2 and c.rules_run == 4 + 3 + 3 + 4 + 4
    assert e.full_started == 0.04  # passing over nothing counts as full for F


async def test_a_wake_and_a_robotless_wake_together_make_a_full_activation() -> None:
    f = Fixture()
    await f.tick(0.0)
    f.e.wake("r1")
    f.e.hurry()  # a rule's hurry for anything
    assert await f.tick(0.01) == ["meta", "a1", "a2", "b1"]


async def test_f_after_the_last_full_activation_runs_all_under_a_stream_of_wakes() -> None:
    f = Fixture()
    e = f.e
    assert await f.tick(0.0) == ["meta", "a1", "a2", "b1"]  # full: F due at 0.05
    ran_a2 = []
    for ms in range(5, 50, 5):  # a wake for r1 every 5 ms
        e.wake("r1")
        ran = await f.tick(ms / 1000)
        assert ran == ["meta", "a1", "b1"], ms  # focused: F not due yet
        ran_a2.append("a2" in ran)
        assert e.full_started == 0.0  # focused ones do not put F off
    e.wake("r1")
    assert await f.tick(0.05) == ["a2", "meta", "a1", "b1"]  # F passed: full
    assert e.full_started == 0.05
    e.wake("r1")
    assert await f.tick(0.055) == ["meta", "a1", "b1"]  # focused again, F due at 0.10
    assert not any(ran_a2)


async def test_the_loop_runs_a_full_activation_every_f_under_a_stream_of_wakes() -> None:
    """Through ``Engine.run`` on the wall clock: r1 is woken every 2 ms for 0.5 s, F = 50 ms.
    Were F counted from the last start, as before, r2's rule would never run again."""
    journal: list[str] = []
    e = Engine(EngineSettings(period_s=0.05), name="stream")
    e.add_meta(lambda: Meta("meta", None, journal))
    e.add(Bot("a1", "r1", journal))
    e.add(Bot("a2", "r2", journal))
    task = asyncio.create_task(e.run())
    loop = asyncio.get_running_loop()
    end = loop.time() + 0.5
    while loop.time() < end:
        e.wake("r1")
        await asyncio.sleep(0.002)
    e.stop()
    await asyncio.wait_for(task, 2)
    c = e.counters
    # every F at most (a loaded machine can only make fewer wakes, so fewer focused ones)
    assert journal.count("a2") >= 3 and c.full_activations >= 3
    assert c.focused_activations > c.full_activations
    assert journal.count("a1") == journal.count("meta") == c.activations


async def test_hurry_for_a_robot_focuses_the_next_activation_on_it() -> None:
    f = Fixture(seed=False)
    e, j = f.e, f.journal
    target = Once("t2", "r2", j)
    e.add_meta(lambda: Meta("meta", None, j, spawn=(target,), engine=e, hurry="r2"))
    e.add(Bot("a1", "r1", j))
    e.add(Bot("a2", "r2", j))
    assert await f.tick(0.0) == ["meta", "a1", "a2"]  # meta made t2 and hurried r2
    assert queue(e) == ["t2", "meta", "a1", "a2"]
    assert e.signals.hurried and e.signals.asked == ["r2"]
    assert await f.tick(0.01) == ["t2", "meta", "a2"]  # focused on r2: a1 waits
    assert queue(e) == ["a1", "meta", "a2"]
    assert e.counters.woken_by_rule == 0  # ``tick`` counts no reasons; ``run`` does


async def test_a_rule_generated_for_a_robot_out_of_focus_waits_for_its_wake_or_f() -> None:
    f = Fixture(seed=False)
    e, j = f.e, f.journal
    e.add_meta(lambda: Meta("meta", None, j))
    await f.tick(0.0)
    e.add(Bot("m1", None, j, spawn=(Once("t3", "r3", j),)))  # generates r3's target
    e.wake("r1")
    assert await f.tick(0.01) == ["meta", "m1"]
    assert queue(e) == ["meta", "t3", "m1"]
    e.wake("r1")
    assert await f.tick(0.02) == ["meta", "m1"]  # t3 is r3's: it waits
    assert queue(e) == ["t3", "meta", "m1"]
    e.wake("r3")
    assert await f.tick(0.03) == ["t3", "meta", "m1"]
    assert queue(e) == ["meta", "m1"]


async def test_n_counts_only_the_rules_that_ran_and_a_cut_makes_the_next_one_full() -> None:
    f = Fixture(max_rules=2, seed=False)
    e, j = f.e, f.journal
    for tag, robot in (("a1", "r1"), ("a2", "r2"), ("a3", "r2"), ("b1", "r1"), ("c1", "r1")):
        e.add(Once(tag, robot, j))
    f.first = False  # as if an earlier full activation had run
    e.full_started = 0.0
    e.wake("r1")
    assert await f.tick(0.01) == ["a1", "b1"]  # a2, a3 passed over, not counted
    assert queue(e) == ["a2", "a3", "c1"]  # passed-over ones first, then the leftover
    assert e.counters.capped_by_n == 1 and e.counters.out_of_focus == 2
    e.wake("r1")  # N cut the last one: this one is full, what the cut left runs first
    assert await f.tick(0.02) == ["a2", "a3"]
    assert queue(e) == ["c1"] and e.counters.capped_by_n == 2
    e.wake("r2")  # cut again: full
    assert await f.tick(0.03) == ["c1"]
    assert queue(e) == [] and e.counters.rules_run == 5
    c = e.counters
    assert (c.focused_activations, c.full_activations, c.out_of_focus) == (1, 2, 2)
    e.add(Once("d2", "r2", j))
    e.add(Once("d1", "r1", j))
    e.wake("r1")  # not cut: focused again
    assert await f.tick(0.04) == ["d1"] and queue(e) == ["d2"]


async def test_f_bounds_a_focused_activation_between_the_rules_that_run() -> None:
    f = Fixture(seed=False)
    e, j = f.e, f.journal

    class Slow(Once):
        def actions(self) -> None:
            super().actions()
            f.now += 0.06  # longer than F

    e.add(Slow("s1", "r1", j))
    e.add(Once("a2", "r2", j))
    e.add(Once("b1", "r1", j))
    f.first, e.full_started = False, 0.0
    e.wake("r1")
    assert await f.tick(0.01) == ["s1"]  # F elapsed after s1: b1 waits
    assert queue(e) == ["a2", "b1"] and e.counters.capped_by_f == 1
    e.wake("r1")  # F cut the last one: this one is full
    assert await f.tick(0.08) == ["a2", "b1"]


def test_a_flag_set_with_no_robot_recorded_makes_a_full_activation() -> None:
    e = Engine(EngineSettings(period_s=0.05), clock=lambda: 0.01)
    e.full_started = 0.0
    e.signals.woken = True  # set directly (the monolith's first activation does)
    e.signals.take()
    assert e.focus() is None
    e.wake("r1")
    e.wake("r2")
    e.wake("r1")
    e.signals.take()
    assert e.focus() == frozenset({"r1", "r2"})
    assert e.signals.asked == []  # taken: the next activation starts afresh
    e.wake("r1")
    assert e.focus(first=True) is None  # the first activation is always full


async def test_wake_threadsafe_records_its_robot_before_its_flag() -> None:
    e = Engine(EngineSettings(period_s=10.0))
    e.full_started = e.clock()  # as if a full activation had just run (F = 10 s: not due)
    e.signals.attach()
    thread = threading.Thread(target=e.wake_threadsafe, args=("r7",))
    thread.start()
    thread.join()
    assert e.signals.woken and e.signals.asked == ["r7"]
    e.signals.take()
    assert e.focus() == frozenset({"r7"})


# -- in a lockstep run: F in sim time, from the last full activation -----------------------------
@pytest.fixture
def ledger(zenoh_settings: ZenohSettings) -> Iterator[Ledger]:
    session = bus.open_session(zenoh_settings)
    led = Ledger(session, "planner", "p-1")
    try:
        yield led
    finally:
        led.close()
        session.close()


async def test_lockstep_runs_a_full_activation_when_f_passed_in_sim_time(ledger: Ledger) -> None:
    sim_now = [0.0]
    journal: list[str] = []
    e = Engine(
        EngineSettings(period_s=0.05),
        name="t",
        trigger=LockstepTrigger(ledger),
        clock=lambda: sim_now[0],
    )
    e.add_meta(lambda: Meta("meta", None, journal))
    e.add(Bot("a1", "r1", journal))
    e.add(Bot("a2", "r2", journal))
    clock_tally = ledger.tally(keys.SIM_CLOCK)
    assert clock_tally is not None
    task = asyncio.create_task(e.run())
    try:
        await eventually(lambda: ledger.reports >= 1)
        assert journal == ["meta", "a1", "a2"]  # the first: full, at sim time 0
        for step in range(1, 5):  # a wake for r1 every 0.01 s of sim time
            reports = ledger.reports
            sim_now[0] = step / 100
            e.wake("r1")
            ledger.received(clock_tally, keys.SIM_CLOCK)
            await eventually(lambda seen=reports: ledger.reports > seen)  # type: ignore[misc]
        assert journal[3:] == ["meta", "a1"] * 4  # focused: a2 waits
        reports = ledger.reports
        sim_now[0] = 0.05  # F since the last full one, although one started 0.01 s ago
        e.wake("r1")
        ledger.received(clock_tally, keys.SIM_CLOCK)
        await eventually(lambda: ledger.reports > reports)
        assert journal[11:] == ["a2", "meta", "a1"]
        assert e.full_started == 0.05 and e.counters.focused_activations == 4
    finally:
        e.stop()
        await asyncio.wait_for(task, 5)

"""The Proactive Engine's semantics, activation by activation (docs/ARCHITECTURE.md, *The engine*).

Each test writes the expected queue state beside each step. ``Probe`` rules append their name
to a shared journal when their steps run, so a test reads exactly what ran and in what order.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Iterable, Iterator

import pytest

from common.config import EngineSettings
from common.engine import Engine, Rule
from common.engine.engine import rules_in
from common.engine.trigger import Clock, Signals


class Probe(Rule):
    """A rule that records its steps in a journal and can be told how to behave."""

    scenario = "probe"

    def __init__(
        self,
        tag: str,
        journal: list[str],
        *,
        guard: object = True,
        condition: object = True,
        children: Iterable[Rule] = (),
        fail_in: str = "",
    ) -> None:
        self.tag = tag
        self.journal = journal
        self.guard = guard
        self.condition = condition
        self.children = list(children)
        self.fail_in = fail_in

    def data_acquisition(self) -> None:
        self.journal.append(f"{self.tag}:acquire")
        if self.fail_in == "acquire":
            raise RuntimeError("sensor unavailable")

    def activation_guards(self) -> Iterator[object]:
        yield self.guard

    def conditions(self) -> Iterator[object]:
        self.journal.append(f"{self.tag}:conditions")
        yield self.condition

    def actions(self) -> None:
        self.journal.append(f"{self.tag}:act")
        if self.fail_in == "actions":
            raise ValueError("actuator refused")

    def rule_generation(self) -> list[Rule]:
        self.journal.append(f"{self.tag}:generate")
        return self.children


def ran(journal: list[str]) -> list[str]:
    """Tags of the rules whose acquisition ran, in order."""
    return [entry.split(":")[0] for entry in journal if entry.endswith(":acquire")]


class Meta(Rule):
    """A continuous rule: clones itself every time it runs."""

    scenario = "meta"
    meta = True

    def __init__(self, journal: list[str]) -> None:
        self.journal = journal

    def actions(self) -> None:
        self.journal.append("meta")

    def rule_generation(self) -> list[Rule]:
        return [self.clone()]


def engine(max_rules: int = 100, period_s: float = 10.0) -> Engine:
    return Engine(EngineSettings(period_s=period_s, max_rules=max_rules), name="test")


async def test_rules_run_in_fifo_order() -> None:
    journal: list[str] = []
    e = engine()
    for tag in "abc":
        e.add(Probe(tag, journal))
    assert await e.activation() == 3  # current: a b c -> all run
    assert ran(journal) == ["a", "b", "c"]
    assert len(e) == 0  # target rules end after running


async def test_the_five_steps_run_in_order() -> None:
    journal: list[str] = []
    e = engine()
    e.add(Probe("a", journal))
    await e.activation()
    assert journal == ["a:acquire", "a:conditions", "a:act", "a:generate"]


async def test_n_caps_an_activation_and_leftovers_run_first_next_time() -> None:
    journal: list[str] = []
    e = engine(max_rules=2)
    child = Probe("child", journal)
    e.add(Probe("a", journal, children=[child]))
    e.add(Probe("b", journal))
    e.add(Probe("c", journal))
    # activation 1: current a b c, N=2 -> a, b run; c is left over; next: child
    assert await e.activation() == 2
    assert ran(journal) == ["a", "b"]
    assert rules_in(e.current) == ["Probe", "Probe"]  # c, then child appended
    assert e.current[0].tag == "c" and e.current[1].tag == "child"  # type: ignore[attr-defined]
    assert e.counters.capped_by_n == 1
    # activation 2: the leftover c runs before the generated child
    journal.clear()
    assert await e.activation() == 2
    assert ran(journal) == ["c", "child"]


async def test_f_bounds_an_activation_between_rules() -> None:
    journal: list[str] = []
    e = engine(period_s=1.0)
    now = [0.0]
    e.clock = lambda: now[0]

    class Slow(Probe):
        def actions(self) -> None:
            super().actions()
            now[0] += 0.4  # each rule takes 0.4 s of the engine's clock

    for tag in "abcd":
        e.add(Slow(tag, journal))
    # activation 1: a (0.4) b (0.8) c (1.2 >= F) -> d waits
    assert await e.activation() == 3
    assert ran(journal) == ["a", "b", "c"]
    assert e.counters.capped_by_f == 1
    journal.clear()
    assert await e.activation() == 1
    assert ran(journal) == ["d"]


async def test_a_rule_longer_than_f_still_runs_alone() -> None:
    journal: list[str] = []
    e = engine(period_s=0.1)
    now = [0.0]
    e.clock = lambda: now[0]

    class VerySlow(Probe):
        def actions(self) -> None:
            now[0] += 5.0

    e.add(VerySlow("a", journal))
    e.add(Probe("b", journal))
    assert await e.activation() == 1  # the first rule always runs, then F has elapsed
    assert await e.activation() == 1


async def test_rule_generation_runs_when_the_guard_fails() -> None:
    journal: list[str] = []
    e = engine()
    child = Probe("child", journal)
    e.add(Probe("a", journal, guard=False, children=[child]))
    await e.activation()
    # guard false: no conditions, no actions, but generation ran
    assert journal == ["a:acquire", "a:generate"]
    assert list(e.current) == [child]
    stats = e.stats_for(Probe)
    assert (stats.executed, stats.activated, stats.acted) == (1, 0, 0)


async def test_failed_condition_skips_actions_but_not_generation() -> None:
    journal: list[str] = []
    e = engine()
    e.add(Probe("a", journal, condition=False))
    await e.activation()
    assert journal == ["a:acquire", "a:conditions", "a:generate"]
    stats = e.stats_for(Probe)
    assert (stats.executed, stats.activated, stats.acted) == (1, 1, 0)


async def test_a_self_cloning_meta_rule_runs_once_per_activation() -> None:
    journal: list[str] = []
    e = engine()
    e.add_meta(lambda: Meta(journal))
    for expected in range(1, 6):
        await e.activation()
        assert journal.count("meta") == expected  # once per activation, never twice
        assert len(e.current) == 1 and len(e.next) == 0


async def test_a_target_scenario_ends_after_its_task() -> None:
    journal: list[str] = []
    e = engine()

    class Countdown(Rule):
        """A target rule that clones itself while its task lasts (three steps)."""

        def __init__(self, left: int) -> None:
            self.left = left

        def actions(self) -> None:
            journal.append(f"step{self.left}")

        def rule_generation(self) -> list[Rule]:
            return [Countdown(self.left - 1)] if self.left > 1 else []

    e.add(Countdown(3))
    for _ in range(5):
        await e.activation()
    assert journal == ["step3", "step2", "step1"]
    assert len(e) == 0


async def test_an_exception_in_actions_is_logged_and_the_engine_goes_on(
    caplog: pytest.LogCaptureFixture,
) -> None:
    journal: list[str] = []
    e = engine()
    orphan = Probe("orphan", journal)
    e.add(Probe("bad", journal, fail_in="actions", children=[orphan]))
    e.add(Probe("good", journal))
    with caplog.at_level(logging.ERROR, logger="pnav.engine"):
        assert await e.activation() == 2
    # bad: acquired, acted (and raised), no generation; good ran after it
    assert journal == [
        "bad:acquire",
        "bad:conditions",
        "bad:act",
        "good:acquire",
        "good:conditions",
        "good:act",
        "good:generate",
    ]
    assert len(e) == 0  # the orphan was never generated
    record = next(r for r in caplog.records if "actions" in r.getMessage())
    assert record.rule == "Probe"  # type: ignore[attr-defined]
    assert record.exc_info is not None
    assert e.stats_for(Probe).errors == 1


async def test_an_exception_in_data_acquisition_discards_the_rule() -> None:
    journal: list[str] = []
    e = engine()
    e.add(Probe("bad", journal, fail_in="acquire", children=[Probe("x", journal)]))
    await e.activation()
    assert journal == ["bad:acquire"]
    assert len(e) == 0


async def test_a_meta_rule_lost_to_an_error_is_reseeded() -> None:
    journal: list[str] = []
    e = engine()
    failures = [True]

    class Flaky(Meta):
        def actions(self) -> None:
            if failures and failures.pop():
                raise ConnectionError("database restarting")
            super().actions()

    e.add_meta(lambda: Flaky(journal))
    await e.activation()  # raises, discarded, re-seeded into next
    assert journal == [] and e.counters.meta_reseeded == 1
    await e.activation()  # the re-seeded rule runs and clones itself again
    await e.activation()
    assert journal == ["meta", "meta"]


async def test_an_invalid_guard_result_counts_as_false(caplog: pytest.LogCaptureFixture) -> None:
    journal: list[str] = []
    e = engine()
    e.add(Probe("a", journal, guard="yes"))
    with caplog.at_level(logging.ERROR, logger="pnav.engine"):
        await e.activation()
    assert "a:act" not in journal and "a:generate" in journal
    assert "not a bool" in caplog.text
    assert e.stats_for(Probe).errors == 1


async def test_a_raising_guard_counts_as_false_and_generation_still_runs() -> None:
    journal: list[str] = []
    e = engine()

    class Broken(Probe):
        def activation_guards(self) -> bool:
            raise ZeroDivisionError

    e.add(Broken("a", journal, children=[Probe("b", journal)]))
    await e.activation()
    await e.activation()
    assert ran(journal) == ["a", "b"]


async def test_generation_of_a_non_rule_is_ignored_and_counted() -> None:
    journal: list[str] = []
    e = engine()
    e.add(Probe("a", journal, children=["not a rule", Probe("b", journal)]))  # type: ignore[list-item]
    await e.activation()
    assert len(e.current) == 1 and e.stats_for(Probe).errors == 1


async def test_async_steps_are_awaited() -> None:
    journal: list[str] = []
    e = engine()

    class Reader(Rule):
        async def data_acquisition(self) -> None:
            await asyncio.sleep(0)
            self.value = 42

        def activation_guards(self) -> bool:
            return self.value == 42

        async def actions(self) -> None:
            await asyncio.sleep(0)
            journal.append("acted")

    e.add(Reader())
    await e.activation()
    assert journal == ["acted"]


async def test_statistics_count_per_rule_type() -> None:
    journal: list[str] = []
    e = engine()
    e.add(Probe("a", journal))
    e.add(Probe("b", journal, guard=False))
    e.add(Probe("c", journal, fail_in="actions"))
    await e.activation()
    s = e.stats_for(Probe)
    assert (s.executed, s.activated, s.acted, s.errors) == (3, 2, 1, 1)
    assert s.scenario == "probe" and s.total_time_s >= s.max_time_s > 0


def test_add_refuses_what_is_not_a_rule() -> None:
    with pytest.raises(TypeError):
        engine().add("rule")  # type: ignore[arg-type]


def test_add_meta_refuses_a_target_rule() -> None:
    with pytest.raises(TypeError, match="not a meta rule"):
        engine().add_meta(lambda: Probe("a", []))


def test_watched_tables_come_from_meta_rules() -> None:
    class WatchesOdometry(Meta):
        watches = ("odometry", "goal")

    e = engine()
    e.add_meta(lambda: WatchesOdometry([]))
    assert e.watched_tables == ("goal", "odometry")


# -- the activation loop ----------------------------------------------------------------------


async def test_the_loop_falls_back_to_period_f_without_notifications() -> None:
    journal: list[str] = []
    e = engine(period_s=0.05)
    e.add_meta(lambda: Meta(journal))
    task = asyncio.create_task(e.run())
    await asyncio.sleep(0.5)
    e.stop()
    await asyncio.wait_for(task, 2)
    # about 10 activations in 0.5 s at F = 50 ms; generous bounds for a loaded machine
    assert 3 <= journal.count("meta") <= 12
    assert e.counters.woken_by_notification == 0


async def test_wake_starts_an_activation_before_f() -> None:
    journal: list[str] = []
    e = engine(period_s=30.0)
    e.add_meta(lambda: Meta(journal))
    task = asyncio.create_task(e.run())
    await asyncio.sleep(0.05)
    assert journal.count("meta") == 1  # the first activation, then a wait of F = 30 s
    for expected in (2, 3, 4):
        e.wake()
        await asyncio.sleep(0.05)
        assert journal.count("meta") == expected
    e.stop()
    await asyncio.wait_for(task, 2)
    assert e.counters.woken_by_notification == 3


async def test_pause_p_separates_activations() -> None:
    journal: list[str] = []
    e = Engine(EngineSettings(period_s=0.01, max_rules=10, pause_s=0.2))
    e.add_meta(lambda: Meta(journal))
    task = asyncio.create_task(e.run())
    await asyncio.sleep(0.5)
    e.wake()
    e.stop()
    await asyncio.wait_for(task, 2)
    # each activation is followed by >= 0.2 s: at most 3 in 0.5 s despite F = 10 ms
    assert 1 <= journal.count("meta") <= 3


async def test_stop_lets_the_activation_under_way_finish() -> None:
    journal: list[str] = []
    e = engine(period_s=10.0)
    started = asyncio.Event()

    class Long(Rule):
        async def actions(self) -> None:
            started.set()
            await asyncio.sleep(0.1)
            journal.append("finished")

    e.add(Long())
    e.add(Probe("after", journal))
    task = asyncio.create_task(e.run())
    await started.wait()
    e.stop()
    await asyncio.wait_for(task, 2)
    assert journal[0] == "finished" and "after:act" in journal


async def test_under_way_names_the_activation_running_and_resolves_when_it_ends() -> None:
    e = engine()
    assert e.under_way() is None  # idle: nothing to wait for
    release = asyncio.Event()
    seen: list[asyncio.Future[None] | None] = []

    class Writing(Rule):
        async def actions(self) -> None:
            seen.append(e.under_way())
            await release.wait()  # a write in flight

    e.add(Writing())
    activation = asyncio.create_task(e.activation())
    await asyncio.sleep(0.01)
    during = e.under_way()
    assert during is not None and seen == [during]  # the one future of this activation
    assert not during.done()  # the write is still in flight
    release.set()
    await activation
    assert during.done()  # resolved with the activation's end
    assert e.under_way() is None


async def test_under_way_resolves_even_when_the_activation_is_cancelled() -> None:
    e = engine()

    class Hung(Rule):
        async def actions(self) -> None:
            await asyncio.Event().wait()

    e.add(Hung())
    activation = asyncio.create_task(e.activation())
    await asyncio.sleep(0.01)
    during = e.under_way()
    assert during is not None and not during.done()
    activation.cancel()
    with pytest.raises(asyncio.CancelledError):
        await activation
    assert during.done() and e.under_way() is None


async def test_the_engine_runs_under_uvloop() -> None:
    import uvloop

    assert isinstance(asyncio.get_running_loop(), uvloop.Loop)


async def test_hurry_runs_generated_targets_without_waiting_for_f() -> None:
    journal: list[str] = []
    e = engine(period_s=30.0)

    class Spawner(Rule):
        """Generates one target rule and asks for the next activation at once."""

        def actions(self) -> None:
            e.hurry()

        def rule_generation(self) -> list[Rule]:
            return [Probe("target", journal)]

    e.add(Spawner())
    task = asyncio.create_task(e.run())
    await asyncio.sleep(0.1)
    # activation 1: Spawner (target -> next); activation 2 at once: target runs
    assert ran(journal) == ["target"]
    assert e.counters.woken_by_rule == 1 and e.counters.woken_by_notification == 0
    e.stop()
    await asyncio.wait_for(task, 2)


async def test_wake_threadsafe_from_another_thread_starts_an_activation() -> None:
    journal: list[str] = []
    e = engine(period_s=30.0)
    e.add_meta(lambda: Meta(journal))
    task = asyncio.create_task(e.run())
    await asyncio.sleep(0.05)
    assert journal.count("meta") == 1  # the first activation, then a wait of F = 30 s
    waker = threading.Thread(target=e.wake_threadsafe)
    waker.start()
    waker.join()
    await asyncio.sleep(0.05)
    assert journal.count("meta") == 2
    assert e.counters.woken_by_notification == 1
    e.stop()
    await asyncio.wait_for(task, 2)


class Ticks:
    """A trigger that starts an activation per tick put in its queue (a test's own seam)."""

    def __init__(self) -> None:
        self.ticks: asyncio.Queue[None] = asyncio.Queue()
        self.seen: list[tuple[float | None, bool]] = []

    def bind(self, signals: Signals) -> None:
        return None

    async def wait(
        self, signals: Signals, since: float | None, clock: Clock, settings: EngineSettings
    ) -> None:
        while not signals.stopping:
            if not self.ticks.empty():
                self.ticks.get_nowait()
                self.seen.append((since, signals.pending))
                return
            await signals.wait(0.01)


async def test_a_plugged_trigger_and_clock_decide_when_activations_start() -> None:
    journal: list[str] = []
    now = [100.0]
    trigger = Ticks()
    e = Engine(EngineSettings(period_s=0.001), trigger=trigger, clock=lambda: now[0])
    e.add_meta(lambda: Meta(journal))
    task = asyncio.create_task(e.run())
    await asyncio.sleep(0.05)
    assert journal == []  # no tick: no activation, F or not
    trigger.ticks.put_nowait(None)
    await asyncio.sleep(0.05)
    assert journal == ["meta"] and trigger.seen == [(None, False)]
    now[0] = 101.0
    e.wake()  # the trigger sees the flag, still waits for its tick
    await asyncio.sleep(0.05)
    assert journal == ["meta"]
    trigger.ticks.put_nowait(None)
    await asyncio.sleep(0.05)
    # ``since`` is the previous start on the plugged clock; the wake named this one
    assert journal == ["meta", "meta"] and trigger.seen[1] == (100.0, True)
    assert e.counters.woken_by_notification == 1
    e.stop()
    await asyncio.wait_for(task, 2)

"""Safety rules first, and rules over their time budget (docs/ENGINE.md, "Bounded work"),
activation by activation.

A heavy rule (one robot's dwa, say) moves the engine's hand-moved clock as it runs; safety
rules (each robot's safety_stop) sit anywhere in the queue. Beside each step: what ran, and
the queue after it.
"""

from __future__ import annotations

import logging
import time

import pytest

from common.config import EngineSettings
from common.engine import Engine, Rule

LOGGER = "pnav.engine"


class Bot(Rule):
    """A continuous rule of one robot: records its tag, clones itself."""

    scenario = "bot"

    def __init__(self, tag: str, robot: str | None, journal: list[str]) -> None:
        self.tag, self.robot_id, self.journal = tag, robot, journal

    def actions(self) -> None:
        self.journal.append(self.tag)

    def rule_generation(self) -> list[Rule]:
        return [self.clone()]


class Safety(Bot):
    scenario = "safety_stop"
    safety = True


class Meta(Bot):
    meta = True


class Heavy(Bot):
    """Takes the fixture's ``cost`` s of the engine's clock per run (a dwa decision on
    absurd params); its clones too."""

    scenario = "dwa"

    def __init__(self, tag: str, robot: str, journal: list[str], fixture: Fixture) -> None:
        super().__init__(tag, robot, journal)
        self.fixture = fixture

    def actions(self) -> None:
        super().actions()
        self.fixture.now += self.fixture.cost


class Fixture:
    """F = 50 ms on a hand-moved clock; queue: meta, dwa of r1, avoid of r2, then each
    robot's safety_stop at the end, where a strategy switch would have put them."""

    def __init__(self, max_rules: int = 100) -> None:
        self.now = 0.0
        self.cost = 0.0  # what a run of the heavy rule takes
        self.journal: list[str] = []
        settings = EngineSettings(period_s=0.05, max_rules=max_rules)
        self.e = Engine(settings, clock=lambda: self.now)
        self.e.add_meta(lambda: Meta("meta", None, self.journal))
        self.e.add(Heavy("dwa1", "r1", self.journal, self))
        self.e.add(Bot("avoid2", "r2", self.journal))
        self.e.add(Safety("stop1", "r1", self.journal))
        self.e.add(Safety("stop2", "r2", self.journal))
        self.first = True

    def queue(self) -> list[str]:
        return [r.tag for r in self.e.current]  # type: ignore[attr-defined]

    async def tick(self, at: float) -> list[str]:
        """One activation at ``at``, as ``Engine.run`` starts it; the rules that ran."""
        self.now = at
        self.journal.clear()
        self.e.signals.take()
        await self.e.activation(self.e.focus(self.first))
        self.first = False
        return list(self.journal)


async def test_safety_rules_run_first_in_every_activation_wherever_they_queue() -> None:
    f = Fixture()
    assert f.queue() == ["meta", "dwa1", "avoid2", "stop1", "stop2"]
    # the meta rule at the head first (it says what runs), then the safety rules
    assert await f.tick(0.0) == ["meta", "stop1", "stop2", "dwa1", "avoid2"]
    # the clones queue in the order the rules ran
    assert f.queue() == ["meta", "stop1", "stop2", "dwa1", "avoid2"]
    assert await f.tick(0.01) == ["meta", "stop1", "stop2", "dwa1", "avoid2"]
    assert f.e.counters.safety_run == 4
    assert f.e.counters.rules_run == 10


async def test_a_heavy_rule_over_f_cuts_the_others_never_the_safety_rules() -> None:
    f = Fixture()
    await f.tick(0.0)
    f.cost = 2.4  # the stalled dwa: 2.4 s in one run
    # activation 1: both safety_stops ran before dwa; dwa runs, then F has passed: avoid2
    # waits
    assert await f.tick(0.01) == ["meta", "stop1", "stop2", "dwa1"]
    assert f.queue() == ["avoid2", "meta", "stop1", "stop2", "dwa1"]
    assert f.e.counters.capped_by_f == 1 and f.e.cut
    # activation 2 (full: the last was cut): what the cut left is at the head, so the
    # safety rules first, then it, then dwa, which overruns F and cuts the next one
    f.e.add(Bot("late2", "r2", f.journal))
    assert await f.tick(f.now) == ["stop1", "stop2", "avoid2", "meta", "dwa1"]
    assert f.queue() == ["late2", "stop1", "stop2", "avoid2", "meta", "dwa1"]
    assert await f.tick(f.now) == ["stop1", "stop2", "late2", "avoid2", "meta", "dwa1"]
    assert f.e.counters.capped_by_f == 2
    # whatever dwa costs, every activation ran every robot's safety_stop, before dwa
    assert f.e.stats_for(Safety).executed == 2 * 4
    assert f.e.stats_for(Heavy).executed == 4
    assert f.e.stats_for(Heavy).max_time_s < 2.4  # its statistics time the wall, not F


async def test_n_never_cuts_a_safety_rule() -> None:
    f = Fixture(max_rules=1)
    assert await f.tick(0.0) == ["meta", "stop1", "stop2"]  # N = 1: one of the others
    assert await f.tick(0.01) == ["stop1", "stop2", "dwa1"]
    assert await f.tick(0.02) == ["stop1", "stop2", "avoid2"]
    assert f.e.counters.capped_by_n == 3


async def test_a_focused_activation_runs_its_robots_safety_rules_first() -> None:
    f = Fixture()
    await f.tick(0.0)
    f.e.wake("r2")
    assert await f.tick(0.01) == ["meta", "stop2", "avoid2"]  # stop1 is r1's: passed over
    assert f.queue() == ["stop1", "dwa1", "meta", "stop2", "avoid2"]
    f.e.wake("r1")
    assert await f.tick(0.02) == ["stop1", "dwa1", "meta"]


class Sleepy(Rule):
    """Takes at least ``seconds`` of wall time per run (time.sleep), for the budget."""

    scenario = "dwa"
    robot_id = "r1"

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds

    def actions(self) -> None:
        time.sleep(self.seconds)


class FakeWall:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def budget_lines(caplog: pytest.LogCaptureFixture) -> list[logging.LogRecord]:
    return [r for r in caplog.records if r.name == LOGGER and "time budget" in r.getMessage()]


async def test_a_rule_over_its_budget_is_logged_with_its_time_once_per_window(
    caplog: pytest.LogCaptureFixture,
) -> None:
    wall = FakeWall()
    e = Engine(EngineSettings(period_s=10.0, rule_budget_s=0.001), name="controller")
    e.budget_log.clock = wall
    with caplog.at_level(logging.WARNING, logger=LOGGER):
        for _ in range(5):
            e.add(Sleepy(0.002))  # 2 ms or more: over the 1 ms budget every time
            await e.activation()
        first = budget_lines(caplog)
        assert len(first) == 1  # the first over-run, at once
        text = first[0].getMessage()
        assert text.startswith("rule Sleepy (robot r1) over its time budget: ")
        assert "ms > 1.0 ms (later ones: one line per 10 s)" in text
        assert first[0].time_ms >= 2.0 and first[0].budget_ms == 1.0  # type: ignore[attr-defined]
        assert e.counters.over_budget == 5  # counted every time
        assert e.stats_for(Sleepy).max_time_s >= 0.002

        wall.now += 10.0  # the window passed: the next activation's end sums the four
        await e.activation()  # (one that runs no rule)
        lines = budget_lines(caplog)
        assert len(lines) == 2
        assert "over its time budget 4 times in the last 10.0 s: longest " in (
            lines[1].getMessage()
        )
        assert lines[1].repeated == 4  # type: ignore[attr-defined]

        e.add(Sleepy(0.0))  # well within a budget of 10 s: nothing to say
        e.settings = EngineSettings(period_s=10.0, rule_budget_s=10.0)
        await e.activation()
        assert len(budget_lines(caplog)) == 2 and e.counters.over_budget == 5

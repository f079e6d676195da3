"""A rule failing on every tick logs once per distinct error, then a count, not per tick.

The engine still counts every error in its statistics; only log lines are thinned
(common.engine.errorlog, docs/ENGINE.md).
"""

from __future__ import annotations

import logging
from collections.abc import Iterator

import pytest

from common.config import EngineSettings
from common.engine import Engine, Rule
from common.engine.errorlog import MAX_DISTINCT, ErrorLog

LOGGER = "pnav.engine"


class FakeWall:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


class Failing(Rule):
    """A meta-like target rule that re-adds itself and fails its actions with ``message``."""

    scenario = "probe"
    message = "row 7 has NaN x"

    def actions(self) -> None:
        raise ValueError(self.message)


class BadGuard(Rule):
    scenario = "probe"

    def activation_guards(self) -> Iterator[bool]:
        yield "yes"  # type: ignore[misc]  # the point: a result that is not a bool


def engine(wall: FakeWall) -> Engine:
    e = Engine(EngineSettings(period_s=10.0, max_rules=1000))
    e.error_log.clock = wall
    return e


def lines(caplog: pytest.LogCaptureFixture) -> list[logging.LogRecord]:
    return [r for r in caplog.records if r.name == LOGGER]


async def tick(e: Engine, rule: Rule, times: int) -> None:
    for _ in range(times):
        e.add(rule)
        await e.activation()


async def test_the_same_error_every_tick_logs_once_then_a_count_per_window(
    caplog: pytest.LogCaptureFixture,
) -> None:
    wall = FakeWall()
    e = engine(wall)
    rule = Failing()
    with caplog.at_level(logging.ERROR, logger=LOGGER):
        await tick(e, rule, 100)  # 100 failures within the same wall second
        first = lines(caplog)
        assert len(first) == 1
        assert "error in actions; rule discarded: ValueError: row 7 has NaN x" in (
            first[0].getMessage()
        )
        assert first[0].exc_info is not None  # the first one carries its traceback
        assert e.stats_for(Failing).errors == 100  # counted every time all the same

        wall.now += 9.9
        await tick(e, rule, 50)
        assert len(lines(caplog)) == 1  # still inside the window: silent

        wall.now += 0.2  # past 10 s since the first line
        await tick(e, rule, 1)
        summary = lines(caplog)[1:]
        assert len(summary) == 1
        assert summary[0].getMessage().endswith("(repeated 150 times in the last 10.1 s)")
        assert summary[0].exc_info is None
        assert summary[0].repeated == 150  # type: ignore[attr-defined]
        assert summary[0].rule == "Failing"  # type: ignore[attr-defined]
        assert e.stats_for(Failing).errors == 151


async def test_distinct_errors_are_each_logged_once(caplog: pytest.LogCaptureFixture) -> None:
    wall = FakeWall()
    e = engine(wall)

    class OtherMessage(Failing):
        message = "row 8 has NaN y"

    with caplog.at_level(logging.ERROR, logger=LOGGER):
        await tick(e, Failing(), 5)
        await tick(e, OtherMessage(), 5)  # another rule type
        other = Failing()
        other.message = "row 9 has Infinity tolerance"
        await tick(e, other, 5)  # same type, another message
        await tick(e, BadGuard(), 5)  # an invalid result, no exception
    messages = [r.getMessage() for r in lines(caplog)]
    assert len(messages) == 4, messages
    assert sum("row 7" in m for m in messages) == 1
    assert sum("row 8" in m for m in messages) == 1
    assert sum("row 9" in m for m in messages) == 1
    assert sum("not a bool" in m for m in messages) == 1
    assert e.stats_for(BadGuard).errors == 5


async def test_repeats_are_summarised_when_the_window_ends_even_if_the_error_stopped(
    caplog: pytest.LogCaptureFixture,
) -> None:
    wall = FakeWall()
    e = engine(wall)
    with caplog.at_level(logging.ERROR, logger=LOGGER):
        await tick(e, Failing(), 3)
        wall.now += 11.0
        await e.activation()  # nothing fails now: the flush after the activation reports
        assert lines(caplog)[-1].getMessage().endswith("(repeated 2 times in the last 11.0 s)")
        await e.activation()
        assert len(lines(caplog)) == 2  # reported once, not again


async def test_a_stopping_engine_logs_the_repeats_not_yet_reported(
    caplog: pytest.LogCaptureFixture,
) -> None:
    wall = FakeWall()
    e = engine(wall)
    with caplog.at_level(logging.ERROR, logger=LOGGER):
        await tick(e, Failing(), 4)
        e.stop()
        await e.run()  # stops at once; its finally flushes
    assert lines(caplog)[-1].getMessage().endswith("(repeated 3 times in the last 0.0 s)")


def test_distinct_errors_are_bounded_and_a_forgotten_one_reports_its_count(
    caplog: pytest.LogCaptureFixture,
) -> None:
    wall = FakeWall()
    log = ErrorLog(logging.getLogger(LOGGER), clock=wall)
    with caplog.at_level(logging.ERROR, logger=LOGGER):
        log.report((Rule, "actions", "E", "0"), logging.ERROR, "first", {})
        log.report((Rule, "actions", "E", "0"), logging.ERROR, "first", {})
        for i in range(1, MAX_DISTINCT + 1):  # one more than fits: "0" is forgotten
            log.report((Rule, "actions", "E", str(i)), logging.ERROR, f"e{i}", {})
    messages = [r.getMessage() for r in lines(caplog)]
    assert "first (repeated 1 times in the last 0.0 s)" in messages
    assert len(log._seen) == MAX_DISTINCT

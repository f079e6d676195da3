"""The pure parts of the command path: clamping, the watchdog, settings, rate-limited logs."""

from __future__ import annotations

import logging
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from common.contract.limits import clamp
from common.errors import ConfigError
from services.bridge.counters import Counters, RateLimitedLog
from services.bridge.settings import BridgeSettings
from services.bridge.watchdog import Watchdog


@given(value=st.floats(), limit=st.floats(0, 10))
def test_clamp_stays_within_the_limit_and_is_finite(value: float, limit: float) -> None:
    result = clamp(value, limit)
    assert -limit <= result <= limit and math.isfinite(result)
    if math.isnan(value):
        assert result == 0.0
    elif -limit <= value <= limit:
        assert result == value


def test_clamp_examples() -> None:
    assert clamp(1.0, 0.22) == 0.22
    assert clamp(-5.0, 2.84) == -2.84
    assert clamp(math.inf, 0.22) == 0.22
    assert clamp(math.nan, 0.22) == 0.0
    assert clamp(0.1, math.nan) == 0.0  # a broken limit stops the robot
    assert clamp(0.1, -1.0) == 0.0
    assert clamp(math.inf, math.inf) == 0.0  # never send a non-finite velocity


def test_the_watchdog_trips_once_after_the_timeout() -> None:
    dog = Watchdog(0.5)
    dog.feed("r1", 10.0)
    assert dog.expired(10.49) == []
    assert dog.expired(10.5) == [("r1", 0.5)]
    assert dog.expired(11.0) == []  # once
    assert dog.armed() == set()
    dog.feed("r1", 11.0)  # a fresh command re-arms it
    assert dog.expired(11.2) == []
    assert [robot for robot, _ in dog.expired(11.6)] == ["r1"]


def test_the_watchdog_counts_from_the_first_clock_reading_and_survives_time_going_back() -> None:
    dog = Watchdog(0.5)
    dog.feed("r1", None)  # the command came before the sim clock did
    assert dog.expired(100.0) == []
    assert [r for r, _ in dog.expired(100.5)] == ["r1"]
    dog.feed("r2", 50.0)
    assert dog.expired(3.0) == []  # the sim restarted: count from 3.0
    assert [r for r, _ in dog.expired(3.5)] == ["r2"]
    dog.feed("r3", 1.0)
    dog.disarm("r3")
    assert dog.expired(9.0) == []


def test_settings_from_env() -> None:
    s = BridgeSettings.from_env(
        {"PNAV_BRIDGE_WATCHDOG_S": "0.25", "PNAV_BRIDGE_COMMAND_PERIOD_MS": "20"}
    )
    assert (s.watchdog_s, s.command_period_s, s.prune_period_s) == (0.25, 0.02, 5.0)
    assert BridgeSettings.from_env({}) == BridgeSettings()
    for bad in ("0", "-1", "nan", "soon"):
        with pytest.raises(ConfigError, match="PNAV_BRIDGE_WATCHDOG_S"):
            BridgeSettings.from_env({"PNAV_BRIDGE_WATCHDOG_S": bad})


def test_rate_limited_log_swallows_a_flood_and_says_so(caplog: pytest.LogCaptureFixture) -> None:
    logger = logging.getLogger("test.bridge.flood")
    limited = RateLimitedLog(logger, period_s=3600)
    with caplog.at_level(logging.WARNING, logger=logger.name):
        logged = [limited.warning(("odom", "wrong_type"), "malformed") for _ in range(1000)]
        limited.warning(("scan", "beam_count"), "malformed")
    assert logged.count(True) == 1
    assert len(caplog.records) == 2
    limited.period_s = 0.0
    with caplog.at_level(logging.WARNING, logger=logger.name):
        limited.warning(("odom", "wrong_type"), "malformed")
    assert caplog.records[-1].__dict__["suppressed"] == 999


def test_counters_snapshot_is_json_friendly() -> None:
    c = Counters()
    c.malformed[("odom", "not_finite")] += 2
    c.messages_in["odom"] += 3
    snap = c.snapshot()
    assert snap["malformed"] == {"odom/not_finite": 2}
    assert snap["messages_in"] == {"odom": 3}
    assert c.malformed_total() == 2 and c.malformed_total("scan") == 0

"""Configuration from PNAV_* variables: defaults, parsing, and errors that name the variable."""

from __future__ import annotations

import pytest

from common.bus import zenoh_config
from common.config import DATA_QUEUE_BATCHES, EngineSettings, ServiceConfig, ZenohSettings
from common.errors import ConfigError


def test_defaults_need_only_the_database_url() -> None:
    config = ServiceConfig.from_env("planner", {"PNAV_DATABASE_URL": "postgresql://x/y"})
    assert config.zenoh == ZenohSettings()
    assert config.zenoh.multicast is False
    assert config.engine == EngineSettings(period_s=0.05, max_rules=1000, pause_s=0.0)


def test_a_missing_database_url_says_what_to_do() -> None:
    with pytest.raises(ConfigError, match=r"PNAV_DATABASE_URL.*pnav up"):
        ServiceConfig.from_env("planner", {})


def test_variables_are_read_by_name() -> None:
    env = {
        "PNAV_DATABASE_URL": "postgresql://x/y",
        "PNAV_ZENOH_MODE": "peer",
        "PNAV_ZENOH_CONNECT": "tcp/10.0.0.1:7447, tcp/10.0.0.2:7447",
        "PNAV_ZENOH_MULTICAST": "yes",
        "PNAV_ENGINE_PERIOD_MS": "20",
        "PNAV_ENGINE_MAX_RULES": "50",
        "PNAV_ENGINE_PAUSE_MS": "1.5",
        "PNAV_ENGINE_RULE_BUDGET_MS": "30",
        "PNAV_INSTANCE": "ctl-2",
    }
    config = ServiceConfig.from_env("controller", env)
    assert config.zenoh.mode == "peer"
    assert config.zenoh.connect == ("tcp/10.0.0.1:7447", "tcp/10.0.0.2:7447")
    assert config.zenoh.multicast is True
    assert config.engine == EngineSettings(
        period_s=0.02, max_rules=50, pause_s=0.0015, rule_budget_s=0.03
    )
    assert config.instance == "ctl-2"


@pytest.mark.parametrize(
    ("name", "value", "message"),
    [
        ("PNAV_ENGINE_PERIOD_MS", "fast", "PNAV_ENGINE_PERIOD_MS='fast' is not a number"),
        ("PNAV_ENGINE_PERIOD_MS", "0", "PNAV_ENGINE_PERIOD_MS='0' must be at least"),
        ("PNAV_ENGINE_MAX_RULES", "0", "PNAV_ENGINE_MAX_RULES='0' must be at least 1"),
        ("PNAV_ENGINE_RULE_BUDGET_MS", "0", "PNAV_ENGINE_RULE_BUDGET_MS='0' must be at least"),
        ("PNAV_ZENOH_MULTICAST", "maybe", "PNAV_ZENOH_MULTICAST='maybe' is not a boolean"),
        ("PNAV_ZENOH_MODE", "server", "must be client, peer or router"),
        ("PNAV_ZENOH_DATA_QUEUE", "0", "PNAV_ZENOH_DATA_QUEUE='0' must be at least 1"),
        ("PNAV_ZENOH_DATA_QUEUE", "17", "PNAV_ZENOH_DATA_QUEUE=17 must be 1 to 16 batches"),
        ("PNAV_ZENOH_DATA_QUEUE", "many", "PNAV_ZENOH_DATA_QUEUE='many' is not a whole number"),
    ],
)
def test_a_bad_value_names_its_variable(name: str, value: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        ServiceConfig.from_env("x", {"PNAV_DATABASE_URL": "postgresql://x/y", name: value})


def test_zenoh_settings_round_trip_through_the_environment() -> None:
    settings = ZenohSettings(mode="client", connect=("tcp/127.0.0.1:9999",), multicast=False)
    assert ZenohSettings.from_env(settings.to_env()) == settings
    smaller = ZenohSettings(data_queue=2)
    assert ZenohSettings.from_env(smaller.to_env()) == smaller


def test_every_session_gets_room_for_sixteen_batches_a_link_unless_told_otherwise() -> None:
    # Zenoh's own default is 2, with which a busy machine drops express notifications
    queue = "transport/link/tx/queue/size/data"
    assert ZenohSettings.from_env({}).data_queue == DATA_QUEUE_BATCHES == 16
    assert zenoh_config(ZenohSettings()).get_json(queue) == "16"
    told = ZenohSettings.from_env({"PNAV_ZENOH_DATA_QUEUE": "4"})
    assert zenoh_config(told).get_json(queue) == "4"


def test_the_sim_clock_ignores_reordering_but_follows_a_restarted_sim() -> None:
    from common.clock import SimClock

    clock = SimClock()
    assert clock.now() == 0.0 and not clock.started
    clock.update(100.0, rate=0.0)
    clock.update(99.8, rate=0.0)  # a late message: ignored
    assert clock.now() == 100.0
    clock.update(0.5, rate=0.0)  # far back: the sim restarted
    assert clock.now() == 0.5

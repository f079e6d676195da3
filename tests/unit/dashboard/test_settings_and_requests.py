"""The dashboard's settings and request checks refuse what they must, with the reason."""

from __future__ import annotations

import pytest

from common.errors import ConfigError
from services.dashboard.hub import QUEUE_LIMIT, Hub
from services.dashboard.requests import GoalRequest, NewStrategy, Refused, json_object
from services.dashboard.settings import DashboardSettings


def test_settings_default_to_loopback_on_8080_and_read_the_environment() -> None:
    assert DashboardSettings.from_env({}) == DashboardSettings("127.0.0.1", 8080)
    env = {"PNAV_DASHBOARD_HOST": "0.0.0.0", "PNAV_DASHBOARD_PORT": "9000"}
    assert DashboardSettings.from_env(env).url == "http://0.0.0.0:9000/"


@pytest.mark.parametrize(
    ("env", "message"),
    [
        ({"PNAV_DASHBOARD_PORT": "http"}, "PNAV_DASHBOARD_PORT='http' is not a port number"),
        ({"PNAV_DASHBOARD_PORT": "70000"}, "PNAV_DASHBOARD_PORT=70000 must be from 0 to 65535"),
        ({"PNAV_DASHBOARD_HOST": "a b"}, "PNAV_DASHBOARD_HOST='a b' is not an address"),
    ],
)
def test_a_bad_setting_names_its_variable(env: dict[str, str], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        DashboardSettings.from_env(env)


def test_json_with_nan_is_not_json() -> None:
    with pytest.raises(Refused) as refused:
        json_object(b'{"x": NaN}')
    assert refused.value.status == 400


def test_a_goal_keeps_its_values_and_refuses_the_contracts_bounds() -> None:
    assert GoalRequest.parse({"x": 1, "y": -2.5}) == GoalRequest(1.0, -2.5, None)
    with pytest.raises(Refused, match="goal y must be a finite number"):
        GoalRequest.parse({"x": 1, "y": -2e5})


def test_a_new_strategy_is_upper_case_with_its_scenarios_in_order() -> None:
    new = NewStrategy.parse(
        {"code": " careful ", "controller_scenarios": ["b", "a"], "params": {"k": 1e6}}
    )
    assert (new.code, new.planner_scenario, new.controller_scenarios) == (
        "CAREFUL",
        None,
        ("b", "a"),
    )
    with pytest.raises(Refused, match="names a scenario twice"):
        NewStrategy.parse({"code": "X", "controller_scenarios": ["a", "a"]})


async def test_a_browser_that_falls_behind_is_let_go_with_an_end_mark() -> None:
    hub = Hub()
    slow = hub.join({"type": "snapshot"})
    for i in range(QUEUE_LIMIT):
        hub.broadcast([{"type": "robots", "n": i}])
    assert slow.dropped and slow not in hub.browsers
    assert slow.queue.qsize() == 1 and slow.queue.get_nowait() is None

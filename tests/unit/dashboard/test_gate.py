"""Who may use the dashboard: the Host names it answers and the Origin it takes as its own
page (services.dashboard.gate), and the JSON it refuses to parse (services.dashboard.requests)."""

from __future__ import annotations

import json

import pytest

from common.errors import ConfigError
from services.dashboard import scene
from services.dashboard.gate import AllowedHosts
from services.dashboard.requests import MAX_BODY_DEPTH, Refused, json_depth, json_object
from services.dashboard.settings import DashboardSettings

LOOPBACK = AllowedHosts.of(DashboardSettings())


@pytest.mark.parametrize(
    ("host", "origin"),
    [
        ("127.0.0.1:8080", None),
        ("127.0.0.1:8080", "http://127.0.0.1:8080"),
        ("localhost:8080", "http://localhost:8080"),
        ("LocalHost.:8080", "http://localhost.:8080"),
        ("[::1]:8080", "http://[::1]:8080"),
        ("127.0.0.1", "http://127.0.0.1:80"),  # the default port, said or not
    ],
)
def test_the_dashboards_own_page_passes(host: str, origin: str | None) -> None:
    assert LOOPBACK.refusal(host, origin) is None


@pytest.mark.parametrize(
    ("host", "origin", "why"),
    [
        ("evil.example:8080", "http://evil.example:8080", "DNS rebinding"),
        ("evil.example:8080", None, "DNS rebinding"),
        ("127.0.0.1.evil.example", None, "DNS rebinding"),
        ("user@127.0.0.1:8080", None, "DNS rebinding"),
        ("192.168.1.5:8080", None, "DNS rebinding"),  # not listening on every address
        (None, None, "no Host header"),
        ("127.0.0.1:port", None, "not a host and port"),
        ("127.0.0.1:8080", "https://127.0.0.1:8080", "cross-origin"),
        ("127.0.0.1:8080", "http://127.0.0.1:8081", "cross-origin"),
        ("127.0.0.1:8080", "http://localhost:8080", "cross-origin"),
        ("127.0.0.1:8080", "http://evil.example", "cross-origin"),
        ("127.0.0.1:8080", "null", "cross-origin"),
        ("127.0.0.1:8080", "http://127.0.0.1:8080/path", "cross-origin"),
    ],
)
def test_another_sites_page_is_refused_with_its_reason(
    host: str | None, origin: str | None, why: str
) -> None:
    reason = LOOPBACK.refusal(host, origin)
    assert reason is not None and why in reason


def test_configured_names_and_the_listening_address_are_the_dashboards_own() -> None:
    env = {"PNAV_DASHBOARD_HOST": "10.1.2.3", "PNAV_DASHBOARD_ALLOWED_HOSTS": "Robots.LAN, x"}
    allowed = AllowedHosts.of(DashboardSettings.from_env(env))
    assert allowed.refusal("robots.lan:8080", "http://robots.lan:8080") is None
    assert allowed.refusal("10.1.2.3:8080", None) is None
    assert allowed.refusal("10.1.2.4:8080", None) is not None


def test_listening_on_every_address_any_address_but_no_other_name_is_its_own() -> None:
    allowed = AllowedHosts.of(DashboardSettings(host="0.0.0.0"))
    assert allowed.refusal("192.168.1.5:8080", "http://192.168.1.5:8080") is None
    assert allowed.refusal("[fe80::1]:8080", None) is None
    assert allowed.refusal("printer.lan:8080", None) is not None


@pytest.mark.parametrize("names", ["http://robots.lan", "robots.lan:8080", "a b", "x/y"])
def test_an_allowed_host_is_a_name_only(names: str) -> None:
    with pytest.raises(ConfigError, match="PNAV_DASHBOARD_ALLOWED_HOSTS"):
        DashboardSettings.from_env({"PNAV_DASHBOARD_ALLOWED_HOSTS": names})


def test_json_depth_counts_brackets_outside_strings() -> None:
    assert json_depth('{"a": "[[[{{{", "b": [1, {"c": "\\"]]"}]}') == 3
    assert json_depth("[" * 990 + "]" * 990) == 990


def test_a_body_nested_deeper_than_its_bound_is_refused_before_parsing() -> None:
    with pytest.raises(Refused) as refused:
        json_object(("[" * 990 + "]" * 990).encode())
    assert refused.value.status == 400 and "nests 990 deep" in refused.value.reason
    ok = "[" * (MAX_BODY_DEPTH - 1) + "]" * (MAX_BODY_DEPTH - 1)
    assert json_object(f'{{"k": {ok}}}'.encode())["k"] == json.loads(ok)


def test_what_the_page_draws_stops_at_its_depth() -> None:
    inner: object = 1
    for _ in range(5000):
        inner = {"k": inner}
    drawn = scene.jsonable({"inputs": inner})
    for _ in range(scene.MAX_DEPTH):
        drawn = drawn["inputs" if "inputs" in drawn else "k"]
    assert drawn == scene.TOO_DEEP
    json.dumps(scene.jsonable(inner))  # and it encodes

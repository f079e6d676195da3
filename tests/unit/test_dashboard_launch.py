"""`pnav up` and `pnav demo` serve the dashboard: its options, its process, its port."""

from __future__ import annotations

import socket
from pathlib import Path
from typing import Any

import pytest

from common.config import ZenohSettings
from common.errors import UsageError
from pnav.cli.dashboard_options import dashboard_options
from pnav.cli.parser import build_parser
from pnav.run.embedded_postgres import free_port
from pnav.run.launcher import lockstep_env, resolve_dashboard, service_specs
from pnav.run.local_stack import LocalStack
from pnav.run.stack_options import DashboardOptions, StackOptions


def local() -> LocalStack:
    router: Any = None  # not used to build the specs
    return LocalStack("postgresql://x/y", ZenohSettings(), router, None)


def test_up_serves_it_on_loopback_8080_unless_told_otherwise() -> None:
    parse = build_parser().parse_args
    assert dashboard_options(parse(["up"])) == DashboardOptions("127.0.0.1", 8080)
    told = parse(["up", "--http-port", "9001", "--http-host", "0.0.0.0"])
    assert dashboard_options(told) == DashboardOptions("0.0.0.0", 9001)
    assert dashboard_options(parse(["up", "--no-dashboard"])) is None
    # the demo picks a free port (two demos never collide), printed when it starts
    assert dashboard_options(parse(["demo"])) == DashboardOptions("127.0.0.1", None)


def test_a_bad_port_is_a_one_line_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args(["up", "--http-port", "80000"])
    assert exit_.value.code == 2
    assert "--http-port: must be a port number from 1 to 65535" in capsys.readouterr().err


def test_the_dashboard_is_a_supervised_process_with_its_address_and_no_lockstep() -> None:
    options = resolve_dashboard(StackOptions(dashboard=DashboardOptions(port=None)))
    assert options.dashboard is not None and options.dashboard.port is not None
    specs = {s.name: s for s in service_specs(local(), options, Path("worlds/warehouse.yaml"))}
    spec = specs["dashboard"]
    assert spec.argv[1:] == ["-m", "services.dashboard"]
    assert spec.env["PNAV_DASHBOARD_PORT"] == str(options.dashboard.port)
    assert spec.env["PNAV_DASHBOARD_HOST"] == "127.0.0.1"
    assert spec.env["PNAV_DATABASE_URL"] == "postgresql://x/y"
    # the sim never waits for it: it writes only what people ask for
    assert "dashboard" not in lockstep_env(options)["PNAV_LOCKSTEP"]
    # tests and benchmarks run none unless they ask
    assert "dashboard" not in {s.name for s in service_specs(local(), StackOptions(), Path())}


def test_a_port_in_use_is_refused_before_anything_starts() -> None:
    port = free_port()
    refused = f"cannot listen on 127.0.0.1:{port}.*--http-port"
    with socket.create_server(("127.0.0.1", port)), pytest.raises(UsageError, match=refused):
        resolve_dashboard(StackOptions(dashboard=DashboardOptions(port=port)))


def test_up_allows_the_host_names_it_is_told_and_passes_them_to_the_dashboard(
    capsys: pytest.CaptureFixture[str],
) -> None:
    parse = build_parser().parse_args
    told = parse(["up", "--http-allow-host", "Robots.LAN", "--http-allow-host", "10.0.0.7"])
    options = dashboard_options(told)
    assert options == DashboardOptions("127.0.0.1", 8080, ("robots.lan", "10.0.0.7"))
    stack = StackOptions(dashboard=DashboardOptions(port=free_port(), allowed_hosts=("a.lan",)))
    specs = {s.name: s for s in service_specs(local(), stack, Path("worlds/warehouse.yaml"))}
    assert specs["dashboard"].env["PNAV_DASHBOARD_ALLOWED_HOSTS"] == "a.lan"
    with pytest.raises(SystemExit) as exit_:
        parse(["up", "--http-allow-host", "http://evil.example:80"])
    assert exit_.value.code == 2
    assert "--http-allow-host: must be a host name" in capsys.readouterr().err

"""How a local stack's services share processes (pnav.run.composition): --processes, which
services a host runs, its process spec, and whose log file each of its lines goes to."""

from __future__ import annotations

import sys
from dataclasses import replace as with_fields
from pathlib import Path
from typing import Any

import pytest

from common.config import ZenohSettings
from common.contract import acl
from common.errors import UsageError
from pnav.cli.parser import build_parser
from pnav.run.composition import COMPOSE_AT_MOST_CORES, hosted, parse_processes, resolve_processes
from pnav.run.launcher import parse_replace, service_specs
from pnav.run.local_stack import BusCredentials, LocalStack
from pnav.run.process_supervisor import line_writer
from pnav.run.stack_options import StackOptions

WORLD = Path("worlds/open_room.yaml")
SCENARIO = ("strategy", "planner", "controller", "decision")


def local(bus: BusCredentials | None = None) -> LocalStack:
    router: Any = None  # not used to build the specs
    zenoh = ZenohSettings(connect=("tcp/127.0.0.1:7447",))
    roles = {n: f"postgresql://pnav_{n}:pw-{n}@/y" for n in (*SCENARIO, "bridge", "user")}
    return LocalStack("postgresql://x/y", zenoh, router, None, role_urls=roles, bus=bus)


@pytest.mark.parametrize(
    ("value", "cores", "layout"),
    [
        ("auto", 1, "composed"),
        ("auto", COMPOSE_AT_MOST_CORES, "composed"),
        ("auto", COMPOSE_AT_MOST_CORES + 1, "separate"),
        ("composed", 64, "composed"),
        ("separate", 2, "separate"),
        (" Composed ", 2, "composed"),
    ],
)
def test_auto_composes_on_few_cores_and_an_explicit_choice_wins(
    value: str, cores: int, layout: str
) -> None:
    assert resolve_processes(value, cores) == layout


def test_a_bad_processes_value_is_refused_naming_the_option() -> None:
    with pytest.raises(UsageError, match="--processes 'threads': one of auto, composed, separate"):
        parse_processes("threads")


@pytest.mark.parametrize(
    "argv",
    [
        ["up"],
        ["demo"],
        ["bench", "startup"],
        ["bench", "latency"],
        ["bench", "nav"],
        ["bench", "faults"],
    ],
)
def test_the_commands_that_start_a_stack_take_processes(argv: list[str]) -> None:
    parser = build_parser()
    assert parser.parse_args([*argv, "--processes", "separate"]).processes == "separate"
    assert parser.parse_args(argv).processes is None  # auto, unless PNAV_PROCESSES says
    with pytest.raises(SystemExit) as refused:
        parser.parse_args([*argv, "--processes", "threads"])
    assert refused.value.code == 2


def test_composed_the_four_scenario_services_are_one_host_process_with_their_roles() -> None:
    stack = local()
    specs = service_specs(stack, StackOptions(processes="composed"), WORLD)
    assert [s.name for s in specs] == ["sim", "bridge", "host"]
    host = specs[-1]
    assert host.argv == [sys.executable, "-m", "pnav.run.host", *SCENARIO]
    assert host.parts == SCENARIO
    for name in SCENARIO:
        assert host.env[f"PNAV_DATABASE_URL_{name.upper()}"] == stack.url_for(name)
    assert host.env["PNAV_DATABASE_URL"] == ""  # no service falls back on another's account


def test_the_host_authenticates_as_its_own_identity(tmp_path: Path) -> None:
    bus = BusCredentials.create(tmp_path)
    (host,) = [
        s
        for s in service_specs(local(bus), StackOptions(processes="composed"), WORLD)
        if s.name == "host"
    ]
    identity = acl.host_identity(SCENARIO)
    assert host.env["PNAV_ZENOH_USER"] == identity
    assert host.env["PNAV_ZENOH_PASSWORD"] == bus.passwords[identity]


def test_a_replicated_or_replaced_service_runs_apart_from_the_host() -> None:
    options = StackOptions(
        processes="composed",
        replicas={"controller": 2},
        replace=parse_replace(["planner=python -m other"]),
    )
    assert hosted(options) == ("strategy", "decision")
    names = [s.name for s in service_specs(local(), options, WORLD)]
    assert names == ["sim", "bridge", "host", "planner", "controller-1", "controller-2"]
    # one service left to host is no host at all
    alone = with_fields(options, replicas={"controller": 2, "decision": 2})
    assert hosted(alone) == ()
    assert "host" not in [s.name for s in service_specs(local(), alone, WORLD)]


def test_separate_is_one_process_per_service() -> None:
    options = StackOptions(processes="separate")
    assert hosted(options) == ()
    names = [s.name for s in service_specs(local(), options, WORLD)]
    assert names == ["sim", "bridge", *SCENARIO]


def test_each_line_of_a_host_goes_to_the_log_of_the_service_it_names() -> None:
    at = "2026-11-28T12:00:00.000Z"
    assert line_writer(f"{at} INFO planner connected", SCENARIO, "host", "host") == "planner"
    assert line_writer(f"{at} ERROR host host stopped", SCENARIO, "host", "planner") == "host"
    # a traceback's lines follow the line they belong to
    assert line_writer("Traceback (most recent call last):", SCENARIO, "host", "decision") == (
        "decision"
    )
    # a service the host does not run is not given a file of its own
    assert line_writer(f"{at} INFO sim hello", SCENARIO, "host", "planner") == "host"

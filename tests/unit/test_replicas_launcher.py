"""`pnav up --replicas controller=3`: parsing, and the processes the launcher starts."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from common.config import ZenohSettings
from common.errors import UsageError
from pnav.cli.parser import build_parser
from pnav.run.launcher import parse_replicas, service_specs
from pnav.run.local_stack import LocalStack
from pnav.run.stack_options import StackOptions


def test_replicas_are_repeatable_and_comma_separated() -> None:
    args = build_parser().parse_args(
        ["up", "--robots", "6", "--replicas", "controller=3", "--replicas", "planner=2, decision=2"]
    )
    assert parse_replicas(args.replicas) == {"controller": 3, "planner": 2, "decision": 2}
    assert parse_replicas(build_parser().parse_args(["up"]).replicas) == {}


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("controller", "SERVICE=N"),
        ("sim=2", "only the scenario services"),
        ("bridge=2", "only the scenario services"),
        ("controller=three", "not a whole number"),
        ("controller=0", "between 1 and"),
    ],
)
def test_a_bad_replicas_value_says_why(value: str, message: str) -> None:
    with pytest.raises(UsageError, match=message):
        parse_replicas([value])


def local() -> LocalStack:
    router: Any = None  # not used to build the specs
    zenoh = ZenohSettings(connect=("tcp/127.0.0.1:7447",))
    return LocalStack("postgresql://x/y", zenoh, router, None)


def test_each_replica_is_its_own_supervised_process_with_its_own_instance() -> None:
    options = StackOptions(robots=6, replicas={"controller": 3}, processes="separate")
    specs = service_specs(local(), options, Path("worlds/warehouse.yaml"))
    names = [s.name for s in specs]
    assert names == [
        "sim",
        "bridge",
        "strategy",
        "planner",
        "controller-1",
        "controller-2",
        "controller-3",
        "decision",
    ]
    replicas = [s for s in specs if s.name.startswith("controller-")]
    assert [s.env["PNAV_INSTANCE"] for s in replicas] == [
        "controller-1",
        "controller-2",
        "controller-3",
    ]
    assert all(s.argv[1:] == ["-m", "services.controller"] for s in replicas)
    assert all(s.env["PNAV_DATABASE_URL"] == "postgresql://x/y" for s in replicas)
    sim = specs[0]
    assert sim.argv[sim.argv.index("--robots") + 1] == "6"
    # a service with one process keeps its plain name (and the supervisor's instance name-1)
    assert "PNAV_INSTANCE" not in specs[3].env


def test_a_bare_count_replicates_every_scenario_service() -> None:
    assert parse_replicas(["3"]) == {
        s: 3 for s in ("strategy", "planner", "controller", "decision")
    }
    assert parse_replicas(["2", "controller=4"])["controller"] == 4
    with pytest.raises(UsageError, match="between 1 and"):
        parse_replicas(["0"])


def test_bench_latency_robot_counts() -> None:
    from pnav.cli.options import parse_counts

    assert parse_counts("1,10,50", "--robots") == [1, 10, 50]
    args = build_parser().parse_args(["bench", "latency"])
    assert (args.robots, args.hz, args.seconds) == ("1,10,50", 20.0, 30.0)
    for bad in ("", "0", "a,2"):
        with pytest.raises(UsageError, match="--robots"):
            parse_counts(bad, "--robots")


def test_a_replaced_service_runs_the_given_command_with_the_same_environment() -> None:
    import sys

    from pnav.run.launcher import parse_replace

    replace = parse_replace(["controller=python -m examples.sql_controller --flag 'a b'"])
    assert replace == {
        "controller": [sys.executable, "-m", "examples.sql_controller", "--flag", "a b"]
    }
    options = StackOptions(replace=replace, replicas={"controller": 2}, processes="separate")
    specs = {s.name: s for s in service_specs(local(), options, Path("worlds/open_room.yaml"))}
    for name in ("controller-1", "controller-2"):
        assert specs[name].argv == replace["controller"]
        assert specs[name].env["PNAV_INSTANCE"] == name
    assert specs["planner"].argv[1:] == ["-m", "services.planner"]
    assert specs["planner"].env == {
        k: v for k, v in specs["controller-1"].env.items() if k != "PNAV_INSTANCE"
    }


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("controller", "SERVICE=COMMAND"),
        ("controller=", "SERVICE=COMMAND"),
        ("sim=python -m other", "only a scenario service"),
        ("planner=python 'unclosed", "closing quotation"),
    ],
)
def test_a_bad_replace_value_says_why(value: str, message: str) -> None:
    from pnav.run.launcher import parse_replace

    with pytest.raises(UsageError, match=message):
        parse_replace([value])


def test_up_lockstep_waits_for_every_service_started_but_a_replaced_one() -> None:
    from pnav.run.launcher import lockstep_env, parse_replace

    args = build_parser().parse_args(["up", "--lockstep"])
    assert args.lockstep
    assert lockstep_env(StackOptions()) == {
        "PNAV_LOCKSTEP": "bridge,strategy,planner,controller,decision"
    }
    replaced = StackOptions(replace=parse_replace(["controller=python -m other"]))
    assert lockstep_env(replaced) == {"PNAV_LOCKSTEP": "bridge,strategy,planner,decision"}
    options = StackOptions(extra_env=lockstep_env(StackOptions()))
    specs = service_specs(local(), options, Path("worlds/open_room.yaml"))
    assert {s.env["PNAV_LOCKSTEP"] for s in specs} == {
        "bridge,strategy,planner,controller,decision"
    }


def test_the_model_option_reaches_the_sim_and_only_the_sim() -> None:
    args = build_parser().parse_args(["up", "--model", "jackal"])
    options = StackOptions(model=args.model)
    specs = {s.name: s for s in service_specs(local(), options, Path("worlds/open_room.yaml"))}
    argv = specs["sim"].argv
    assert argv[argv.index("--model") + 1] == "jackal"
    assert all("--model" not in s.argv for name, s in specs.items() if name != "sim")
    plain = service_specs(local(), StackOptions(), Path("worlds/open_room.yaml"))
    assert all("--model" not in s.argv for s in plain)  # the sim's default: the Burger


def test_each_service_connects_as_its_own_role_and_a_replacement_as_the_replaced_one() -> None:
    from dataclasses import replace as with_fields

    from pnav.run.launcher import parse_replace

    roles = {n: f"postgresql://pnav_{n}:pw@/y" for n in ("bridge", "planner", "controller")}
    stack = with_fields(local(), role_urls=roles)
    options = StackOptions(
        replace=parse_replace(["controller=python -m examples.sql_controller"]),
        processes="separate",
    )
    specs = {s.name: s for s in service_specs(stack, options, Path("worlds/open_room.yaml"))}
    assert specs["bridge"].env["PNAV_DATABASE_URL"] == roles["bridge"]
    assert specs["planner"].env["PNAV_DATABASE_URL"] == roles["planner"]
    assert specs["controller"].env["PNAV_DATABASE_URL"] == roles["controller"]
    assert specs["sim"].env["PNAV_DATABASE_URL"] == ""  # no database account at all
    # a role the stack could not set up: the account the stack was given
    assert specs["decision"].env["PNAV_DATABASE_URL"] == "postgresql://x/y"

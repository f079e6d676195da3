"""``pnav bench faults``: which faults, which mission, and a clear refusal of bad options."""

from __future__ import annotations

from pathlib import Path

import pytest

from common.errors import UsageError
from common.trace import CMD_VEL, Tracer
from pnav.bench.faults.bad_goals import bad_goals
from pnav.bench.faults.catalogue import catalogue, mission_goal, select
from pnav.bench.faults.context import FORGED_COMMAND_ID
from pnav.bench.faults.trial import Result, forged_commands_applied
from pnav.bench.faults.verdict import as_json, misses
from pnav.cli import program as cli

ROOT = Path(__file__).resolve().parents[2]


def test_every_fault_of_the_issue_is_in_the_catalogue_once() -> None:
    names = [f.name for f in catalogue()]
    assert len(names) == len(set(names))
    for service in ("sim", "bridge", "strategy", "planner", "controller", "decision"):
        assert f"kill-{service}" in names
    assert {"kill-postgres", "freeze-router-3s", "freeze-router-10s", "spoof-odom"} <= set(names)
    assert "forged-images" in names
    assert "lease-theft" in names
    assert "forged-cmd-vel" in names
    assert [f.name for f in catalogue() if f.kind == "dashboard"] == [
        "deep-params",
        "dns-rebinding",
    ]
    assert "dwa-stall" in names  # issue 28: a strategy row stalling the controller
    assert [f.argv for f in catalogue() if f.kind == "cli"] == [
        ("nan", "1"),
        ("inf", "1"),
        ("1e308", "1"),
        ("1", "1", "--tolerance", "nan"),
        ("1", "1", "--tolerance=-1"),
    ]


def test_only_keeps_the_order_asked_and_refuses_an_unknown_name() -> None:
    assert [f.name for f in select("goal-nan, kill-sim")] == ["goal-nan", "kill-sim"]
    with pytest.raises(UsageError, match=r"unknown fault.*bogus"):
        select("kill-sim,bogus")


def test_bad_goals_land_outside_the_map_and_inside_a_rack() -> None:
    world, goal = mission_goal("warehouse")
    assert goal == (6.0, 1.0)
    points = bad_goals(world)
    assert points["outside"] == (20.2, 18.2)  # 10 m beyond the far corner of a 10.4 m map
    assert points["obstacle"] == (2.5, 2.45)  # the first rack's centre
    with pytest.raises(UsageError, match="has a mission for"):
        mission_goal("open_room")


@pytest.mark.parametrize(
    "argv",
    [["--only", "bogus"], ["--world", "open_room"], ["--rate", "nan"], ["--world", "nowhere"]],
)
def test_a_bad_option_is_one_line_and_exit_2(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    try:
        code = cli.main(["bench", "faults", *argv])
    except SystemExit as exc:  # argparse's own refusals
        code = exc.code  # type: ignore[assignment]
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("pnav")


def test_a_forged_message_that_had_an_effect_misses_a_target() -> None:
    untouched = Result("spoof-odom", "", outcome="reached", safe=True, forged_believed=0)
    assert misses(untouched) == []
    believed = Result("spoof-odom", "", outcome="reached", safe=True, forged_believed=3)
    assert misses(believed) == ["forged messages believed"]
    assert as_json([untouched], {})["targets"]["forged_believed"] == 0


def test_the_forged_commands_are_counted_from_the_sims_own_trace(tmp_path: Path) -> None:
    tracer = Tracer(tmp_path / "trace.csv")
    tracer.record(CMD_VEL, "r1", 41)  # the bridge's, from command2robot ids
    tracer.record(CMD_VEL, "r1", FORGED_COMMAND_ID + 7)
    tracer.record("odom", "r1", FORGED_COMMAND_ID + 1)  # a sensor seq, not a command
    tracer.close()
    assert forged_commands_applied(tmp_path / "trace.csv") == 1
    assert forged_commands_applied(tmp_path / "none.csv") is None

"""`pnav goal | strategy` refuse bad input at the door: one line naming the argument and
what it accepts, exit 2, no traceback, nothing written."""

from __future__ import annotations

import asyncio
import logging
import math
from pathlib import Path
from typing import Any

import asyncpg
import pytest
import yaml

from common.config import ZenohSettings
from common.contract import limits
from common.errors import ContractError
from common.robotmodel import MODELS
from pnav.cli import parser as cli_parser
from pnav.cli import program as cli
from pnav.cli import stack_commands


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """``pnav ARGV`` in this process: (exit code, stdout, stderr). The root logger is put back
    as it was: a command that sets logging up (`pnav up`) would otherwise leave its handler
    and level to every later command of this process, which a command run as its own process
    never has."""
    root = logging.getLogger()
    handlers, level = root.handlers[:], root.level
    try:
        code = cli.main(argv)
    except SystemExit as exc:  # argparse's usage errors exit
        code = int(exc.code or 0)
    finally:
        root.handlers[:] = handlers
        root.setLevel(level)
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line_refusal(code: int, err: str, *needles: str) -> None:
    assert code == 2, err
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err
    for needle in needles:
        assert needle in err, err


@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["goal", "nan", "1"], ["argument x", "finite", "100000", "'nan'"]),
        (["goal", "1", "NaN"], ["argument y", "'NaN'"]),
        (["goal", "inf", "1"], ["argument x", "'inf'"]),
        (["goal", "--", "1", "-inf"], ["argument y", "'-inf'"]),
        (["goal", "1e308", "0"], ["argument x", "'1e308'"]),
        (["goal", "1e400", "0"], ["argument x", "'1e400'"]),
        (["goal", "100000.5", "0"], ["argument x", "within +-100000"]),
        (["goal", "one", "0"], ["argument x", "'one'"]),
        (["goal", "1", "1", "--tolerance", "-1"], ["argument --tolerance", "(0, 100]", "'-1'"]),
        (["goal", "1", "1", "--tolerance", "0"], ["argument --tolerance", "'0'"]),
        (["goal", "1", "1", "--tolerance", "nan"], ["argument --tolerance", "'nan'"]),
        (["goal", "1", "1", "--tolerance", "101"], ["argument --tolerance", "'101'"]),
        (["goal", "1", "1", "--yaw", "nan"], ["argument --yaw", "degrees", "'nan'"]),
        (["goal", "1", "1", "--yaw", "180.5"], ["argument --yaw", "[-180, 180]", "'180.5'"]),
        (["goal", "1", "1", "--yaw", "90", "--yaw-tolerance", "0"], ["--yaw-tolerance", "'0'"]),
        (["goal", "--through", "1,2;3,nan"], ["argument --through", "pose 2 y", "'nan'"]),
        (["goal", "--through", "1,2,nan"], ["argument --through", "pose 1 yaw", "'nan'"]),
        (["goal", "--through", "1,2,3,4"], ["argument --through", "pose 1 must be x,y"]),
        (
            ["goal", "--through", ";".join(f"{i},0" for i in range(10_000))],
            ["argument --through", "at most 1001 poses", "got 10000"],
        ),
        (["strategy", "GOTO AVOID"], ["argument code", "letters, digits and _"]),
        (["strategy", "GOTO;DROP"], ["argument code"]),
        (["strategy", "A" * 65], ["argument code", "at most 64 characters, got 65"]),
        (["goal", "1" * 400, "1"], ["argument x", "within +-100000", "(400 characters)"]),
        (["goal", "1", "9223372036854775808"], ["argument y", "within +-100000"]),
        (["up", "--battery", "nan"], ["argument --battery", "0 to 100"]),
        (["up", "--robots", "0"], ["argument --robots", "1 or more"]),
        (["bench", "latency", "--hz", "inf"], ["argument --hz", "above 0"]),
        (["migrate", "--wait", "-3"], ["argument --wait"]),
    ],
)
def test_a_bad_number_or_code_is_refused_before_anything_connects(
    argv: list[str], needles: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    # no stack and no database here: the refusal must come first, from the arguments alone
    code, _, err = run_cli(argv, capsys)
    assert_one_line_refusal(code, err, *needles)


@pytest.mark.parametrize(
    ("x", "y", "tolerance"),
    [(0.0, -100_000.0, None), (100_000.0, 1.5, 100.0), (-3.0, 2.0, 0.01)],
)
def test_good_goals_pass_the_argument_checks(x: float, y: float, tolerance: float | None) -> None:
    argv = ["goal", "--", str(x), str(y)]
    if tolerance is not None:
        argv[1:1] = ["--tolerance", str(tolerance)]
    args = cli.build_parser().parse_args(argv)
    assert (args.x, args.y, args.tolerance) == (x, y, tolerance)
    limits.check_goal(x, y, tolerance)  # the same values pass the shared check


@pytest.mark.parametrize(
    ("x", "y", "tolerance"),
    [(math.nan, 0.0, None), (0.0, math.inf, None), (1e6, 0.0, None), (1.0, 1.0, -1.0)],
)
def test_the_shared_goal_check_refuses_what_the_goal_table_refuses(
    x: float, y: float, tolerance: float | None
) -> None:
    with pytest.raises(ContractError, match=r"goal (x|y|tolerance) must be"):
        limits.check_goal(x, y, tolerance)


# -- against a database ---------------------------------------------------------------------------
@pytest.fixture
def stack_env(db_url: str, zenoh_settings: ZenohSettings, monkeypatch: pytest.MonkeyPatch) -> str:
    """PNAV_DATABASE_URL and the Zenoh variables of a contract database with robot r1."""

    async def add_robot() -> None:
        conn = await asyncpg.connect(db_url)
        try:
            await conn.execute("INSERT INTO robot (robot_id) VALUES ('r1')")
        finally:
            await conn.close()

    asyncio.run(add_robot())
    monkeypatch.setenv("PNAV_DATABASE_URL", db_url)
    for name, value in zenoh_settings.to_env().items():
        monkeypatch.setenv(name, value)
    return db_url


async def goals(db_url: str) -> list[tuple[float, float, float]]:
    conn = await asyncpg.connect(db_url)
    try:
        rows = await conn.fetch("SELECT x, y, tolerance_m FROM goal ORDER BY id")
    finally:
        await conn.close()
    return [(r["x"], r["y"], r["tolerance_m"]) for r in rows]


def test_an_unknown_strategy_is_refused_with_the_known_ones(
    stack_env: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = run_cli(["strategy", "no_such_thing"], capsys)
    assert_one_line_refusal(
        code,
        err,
        "unknown strategy 'NO_SUCH_THING'",
        "CHARGE, GOTO_AVOID, GOTO_DIRECT, GOTO_DODGE, GOTO_FAST, GOTO_FORESIGHT, GOTO_LEARNED,"
        " IDLE",
    )


def test_a_good_goal_is_written_and_a_database_refusal_is_one_line_too(
    stack_env: str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    code, out, err = run_cli(["goal", "1.5", "-2", "--tolerance", "0.3"], capsys)
    assert code == 0 and "r1: goal 1 set to (1.5, -2.0)" in out, err
    # Another path that skipped the checks in front (here: both disabled) still gets a
    # one-line refusal from the goal table's CHECK, not an asyncpg traceback.
    monkeypatch.setattr(cli_parser, "tolerance", float)
    monkeypatch.setattr(limits, "check_goal", lambda *_: None)
    code, _, err = run_cli(["goal", "1", "1", "--tolerance", "nan"], capsys)
    assert_one_line_refusal(code, err, "database refused", "goal_tolerance_bounded")
    assert asyncio.run(goals(stack_env)) == [(1.5, -2.0, 0.3)]


def test_a_goal_pose_and_a_route_are_written_with_headings_in_radians(
    stack_env: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = run_cli(["goal", "1", "2", "--yaw", "90"], capsys)
    assert code == 0 and "r1: goal 1 set to (1.0, 2.0) facing 90 deg" in out, err
    code, out, err = run_cli(
        ["goal", "--through", "1,0; 2,0,-90; 3,1,180", "--yaw-tolerance", "10"], capsys
    )
    assert code == 0 and "r1: goal 2 set to (3.0, 1.0) facing 180 deg through 2" in out, err

    async def rows() -> tuple[list[tuple[Any, ...]], list[tuple[Any, ...]]]:
        conn = await asyncpg.connect(stack_env)
        try:
            g = await conn.fetch("SELECT id, status, yaw, yaw_tolerance_rad FROM goal ORDER BY id")
            w = await conn.fetch(
                "SELECT seq, x, y, yaw, yaw_tolerance_rad, stop, status FROM goal_waypoint "
                "WHERE goal_id = 2 ORDER BY seq"
            )
        finally:
            await conn.close()
        return [tuple(r) for r in g], [tuple(r) for r in w]

    goal_rows, waypoint_rows = asyncio.run(rows())
    ten = math.radians(10)
    assert goal_rows == [(1, "superseded", math.pi / 2, 0.1), (2, "active", math.pi, ten)]
    assert waypoint_rows == [
        (1, 1.0, 0.0, None, None, False, "pending"),
        (2, 2.0, 0.0, -math.pi / 2, ten, False, "pending"),
    ]
    code, _, err = run_cli(["goal", "1", "2", "--through", "1,0"], capsys)
    assert_one_line_refusal(code, err, "--through gives the goal's pose")
    code, _, err = run_cli(["goal"], capsys)
    assert_one_line_refusal(code, err, "give X Y, or a route with --through")


async def test_set_goal_refuses_before_writing(db_url: str) -> None:
    # set_goal is what every tool calls (pnav goal, the demo); it checks before it writes
    with pytest.raises(ContractError, match="goal x must be"):
        await stack_commands.set_goal(None, "r1", math.nan, 0.0)  # type: ignore[arg-type]
    assert await goals(db_url) == []


@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["up", "--model", "tank"], ["argument --model", "no robot model 'tank'", "jackal"]),
        (["demo", "--model", "tank"], ["argument --model", "no robot model 'tank'"]),
        (["up", "--model", "nowhere/bot.yaml"], ["argument --model", "model file not found"]),
    ],
)
def test_a_bad_robot_model_is_a_one_line_refusal(
    argv: list[str], needles: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = run_cli(argv, capsys)
    assert_one_line_refusal(code, err, *needles)


def test_a_bad_model_file_names_the_file_and_the_field(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bot.yaml"
    doc = yaml.safe_load((MODELS / "jackal.yaml").read_text())
    doc["footprint_radius_m"] = -0.2
    bad.write_text(yaml.safe_dump(doc))
    code, _, err = run_cli(["up", "--model", str(bad)], capsys)
    assert_one_line_refusal(code, err, f"{bad}: footprint_radius_m: must be positive")


def test_a_world_with_a_bad_model_is_refused_before_anything_starts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    world = tmp_path / "bad.yaml"
    robot = {"id": "r1", "x": 1.0, "y": 1.0, "model": {"name": "jackal", "lidar": {"beams": 0}}}
    world.write_text(
        yaml.safe_dump(
            {"map": str(MODELS.parent / "worlds/maps/open_room.yaml"), "robots": [robot]}
        )
    )
    code, _, err = run_cli(["up", "--world", str(world)], capsys)  # refused before any port
    assert_one_line_refusal(
        code, err, f"{world}: robots[0]: model: models/jackal.yaml (overridden): lidar.beams: "
    )

"""`pnav zone add | list | remove`: bad input refused at the door naming the argument (exit
2, one line, nothing written); good zones written, listed and removed against a database,
each write notified so the services apply it at once."""

from __future__ import annotations

import asyncio
import json
import time

import asyncpg
import pytest

from common import bus
from common.config import ZenohSettings
from common.contract import keys
from tests.unit.test_cli_refusals import assert_one_line_refusal, run_cli, stack_env

__all__ = ["stack_env"]  # the fixture, shared


@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (
            ["--keepout", "--polygon", "0,0; 2,2; 2,0; 0,2"],
            ["argument --polygon", "edges 1 and 3 cross"],
        ),
        (["--keepout", "--polygon", "0,0; 2,2"], ["argument --polygon", "at least 3", "open line"]),
        (["--keepout", "--polygon", "0,0; 1,1; 2,2"], ["argument --polygon", "degenerate"]),
        (
            ["--keepout", "--polygon", "0,0; nan,1; 2,0"],
            ["argument --polygon", "vertex 2", "finite"],
        ),
        (
            ["--keepout", "--polygon", "0,0; 2,0; 2,2; 0,0"],
            ["argument --polygon", "closed implicitly"],
        ),
        (
            ["--keepout", "--polygon", "0,0; 2; 2,2"],
            ["argument --polygon", "vertex 2 must be 'x,y'"],
        ),
        (
            ["--speed-limit", "nan", "--polygon", "0,0; 2,0; 2,2"],
            ["argument --speed-limit", "'nan'"],
        ),
        (
            ["--speed-limit", "0", "--polygon", "0,0; 2,0; 2,2"],
            ["argument --speed-limit", "(0, 10]"],
        ),
        (["--speed-limit", "11", "--polygon", "0,0; 2,0; 2,2"], ["argument --speed-limit"]),
        (["--polygon", "0,0; 2,0; 2,2"], ["one of the arguments --keepout --speed-limit"]),
        (["--keepout", "--speed-limit", "1", "--polygon", "0,0; 2,0; 2,2"], ["not allowed with"]),
    ],
)
def test_a_bad_zone_is_refused_before_anything_connects(
    argv: list[str], needles: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = run_cli(["zone", "add", "dock", *argv], capsys)
    assert_one_line_refusal(code, err, *needles)


def test_a_bad_name_is_refused_naming_it(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_cli(["zone", "add", "a b", "--keepout", "--polygon", "0,0;1,0;1,1"], capsys)
    assert_one_line_refusal(code, err, "argument name", "'a b'")


async def zone_rows(db_url: str) -> list[str]:
    conn = await asyncpg.connect(db_url)
    try:
        return [r["name"] for r in await conn.fetch("SELECT name FROM zone ORDER BY name")]
    finally:
        await conn.close()


def test_zones_are_added_listed_and_removed_each_write_notified(
    stack_env: str, zenoh_settings: ZenohSettings, capsys: pytest.CaptureFixture[str]
) -> None:
    heard: list[str] = []
    session = bus.open_session(zenoh_settings)
    listener = session.declare_subscriber(
        keys.notify_watch(keys.ZONE), lambda sample: heard.append(str(sample.key_expr))
    )
    try:
        polygon = "0,0; 2,0; 2,2; 0,2"
        code, out, err = run_cli(["zone", "add", "dock", "--keepout", "--polygon", polygon], capsys)
        assert code == 0 and "zone dock added (keepout)" in out, err
        argv = ["zone", "add", "aisle", "--speed-limit", "0.3", "--polygon", polygon]
        code, out, err = run_cli([*argv, "--robot", "r1"], capsys)
        assert code == 0, err
        code, _, err = run_cli(["zone", "add", "dock", "--keepout", "--polygon", polygon], capsys)
        assert_one_line_refusal(code, err, "name: a zone named 'dock' exists")
        # a robot id the table refuses: named by its option
        code, _, err = run_cli([*argv[:2], "x", *argv[3:], "--robot", "r 1"], capsys)
        assert_one_line_refusal(code, err, "--robot", "robot_id")

        code, out, _ = run_cli(["zone", "list", "--json"], capsys)
        listed = json.loads(out)
        assert [(z["name"], z["kind"], z["max_speed_mps"], z["robot_id"]) for z in listed] == [
            ("aisle", "speed_limit", 0.3, "r1"),
            ("dock", "keepout", None, None),
        ]
        assert listed[1]["xs"] == [0.0, 2.0, 2.0, 0.0]
        code, out, _ = run_cli(["zone", "list"], capsys)
        assert "aisle" in out and "0.3 m/s" in out and "all robots" in out

        code, out, err = run_cli(["zone", "remove", "dock"], capsys)
        assert code == 0 and "zone dock removed" in out, err
        code, _, err = run_cli(["zone", "remove", "dock"], capsys)
        assert_one_line_refusal(code, err, "name: no zone named 'dock'")
        assert asyncio.run(zone_rows(stack_env)) == ["aisle"]
        # two adds and a remove, each notified (delivery is asynchronous: wait for them)
        for _ in range(400):
            if len(heard) >= 3:
                break
            time.sleep(0.05)
        assert heard == [keys.notify_key(keys.ZONE)] * 3
    finally:
        listener.undeclare()
        session.close()

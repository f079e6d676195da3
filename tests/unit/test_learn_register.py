"""`pnav learn register` against a database: a model file is checked at the door (no
learned scenario could run it, or not its version: exit 2, nothing written), a good one is
written to the model table with its metrics and notified, twice is refused; and migration
18's CHECKs refuse model params and names the register cannot hold."""

from __future__ import annotations

import asyncio
import json
import time
from pathlib import Path

import asyncpg
import pytest

from common import bus
from common.config import ZenohSettings
from common.contract import keys
from tests.unit.learn.test_foresight import foresight_doc
from tests.unit.test_cli_refusals import assert_one_line_refusal, run_cli, stack_env

__all__ = ["stack_env"]  # the fixture, shared


async def model_rows(db_url: str) -> list[tuple[str, str, str, dict[str, float]]]:
    conn = await asyncpg.connect(db_url)
    try:
        rows = await conn.fetch("SELECT name, version, path, metrics FROM model ORDER BY name")
    finally:
        await conn.close()
    return [(r["name"], r["version"], r["path"], json.loads(r["metrics"])) for r in rows]


def test_a_model_is_registered_notified_and_refused_twice(
    stack_env: str,
    zenoh_settings: ZenohSettings,
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
) -> None:
    good = tmp_path / "foresight.json"
    good.write_text(json.dumps({**foresight_doc(version="f1"), "metrics": {"recall_0.6": 0.7}}))
    junk = tmp_path / "junk.json"
    junk.write_text('{"format": "pickle"}')

    code, _, err = run_cli(["learn", "register", str(junk)], capsys)
    assert_one_line_refusal(code, err, "not a model a learned scenario can run")
    code, _, err = run_cli(["learn", "register", str(good), "--version", "f2"], capsys)
    assert_one_line_refusal(code, err, "--version 'f2': the file's version is 'f1'")
    assert asyncio.run(model_rows(stack_env)) == []

    heard: list[str] = []
    session = bus.open_session(zenoh_settings)
    listener = session.declare_subscriber(
        keys.notify_watch(keys.MODEL), lambda sample: heard.append(str(sample.key_expr))
    )
    try:
        time.sleep(0.3)  # the subscriber is declared on the router before the write
        argv = ["learn", "register", str(good), "--name", "foresight", "--version", "f1"]
        code, out, err = run_cli(argv, capsys)
        assert code == 0 and f"model foresight version f1 registered: {good}" in out, err
        rows = asyncio.run(model_rows(stack_env))
        assert rows == [("foresight", "f1", str(good), {"recall_0.6": 0.7})]
        deadline = time.monotonic() + 5.0
        while not heard and time.monotonic() < deadline:
            time.sleep(0.05)
        assert heard == [keys.notify_key(keys.MODEL)]
    finally:
        listener.undeclare()
        session.close()
    code, _, err = run_cli(argv, capsys)
    assert_one_line_refusal(code, err, "model 'foresight' version 'f1' is registered already")


@pytest.mark.parametrize(
    ("sql", "constraint"),
    [
        (
            "INSERT INTO strategy (code, params) VALUES ('A', '{\"learned_model\": 3}')",
            "strategy_model_params",
        ),
        (
            "INSERT INTO strategy (code, params)"
            " VALUES ('B', '{\"foresight_model_version\": \"\"}')",
            "strategy_model_params",
        ),
        (
            "INSERT INTO strategy (code, params) VALUES ('C', '{\"foresight_threshold\": 1.5}')",
            "strategy_model_params",
        ),
        (
            "INSERT INTO model (name, version, path) VALUES ('a model', 'v1', '/m.json')",
            "model_name_plain",
        ),
        (
            "INSERT INTO model (name, version, path) VALUES ('m', 'v 1', '/m.json')",
            "model_version_plain",
        ),
    ],
)
async def test_what_the_register_cannot_hold_is_refused(
    db_url: str, sql: str, constraint: str
) -> None:
    conn = await asyncpg.connect(db_url)
    try:
        with pytest.raises(asyncpg.CheckViolationError, match=constraint):
            await conn.execute(sql)
        params = '{"foresight_model": "foresight", "foresight_threshold": 0.7}'
        await conn.execute(f"INSERT INTO strategy (code, params) VALUES ('OK', '{params}')")
        row = await conn.fetchrow("SELECT * FROM strategy WHERE code = 'GOTO_FORESIGHT'")
        assert row["controller_scenarios"] == ["dwa", "foresight", "safety_stop"]
        assert json.loads(row["params"])["foresight_model"] == "foresight.json"
    finally:
        await conn.close()

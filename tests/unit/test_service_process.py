"""A scenario service as a real process: liveliness, SIGTERM drains it, bad config exits 2."""

from __future__ import annotations

import asyncio
import os
import signal
import sys
import time
from pathlib import Path

import asyncpg

from common import bus
from common.config import ZenohSettings
from common.contract import keys

ROOT = Path(__file__).resolve().parents[2]


async def spawn(env: dict[str, str]) -> asyncio.subprocess.Process:
    return await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "tests.unit.ticker_service",
        cwd=ROOT,
        env={**os.environ, **env},
        stderr=asyncio.subprocess.PIPE,
    )


def alive(session: object, service: str) -> list[str]:
    replies = session.liveliness().get(keys.alive_watch(service), timeout=1)  # type: ignore[attr-defined]
    return [str(r.ok.key_expr) for r in replies if r.ok is not None]


async def test_sigterm_drains_the_engine_and_exits_zero(
    db_url: str, zenoh_settings: ZenohSettings
) -> None:
    env = {
        "PNAV_DATABASE_URL": db_url,
        "PNAV_INSTANCE": "proc-1",
        "PNAV_STATS_PERIOD_S": "0.2",
        **zenoh_settings.to_env(),
    }
    process = await spawn(env)
    session = bus.open_session(zenoh_settings)
    try:
        deadline = time.monotonic() + 20
        while not await asyncio.to_thread(alive, session, "ticker"):
            assert time.monotonic() < deadline, "the service never declared its liveliness"
            assert process.returncode is None, "the service died at start-up"
            await asyncio.sleep(0.2)
        await asyncio.sleep(0.5)
        process.send_signal(signal.SIGTERM)
        assert await asyncio.wait_for(process.wait(), 15) == 0
        assert process.stderr is not None
        log = (await process.stderr.read()).decode()
        assert "engine started" in log and "stopped" in log
        assert await asyncio.to_thread(alive, session, "ticker") == []
    finally:
        if process.returncode is None:
            process.kill()
            await process.wait()
        session.close()
    conn = await asyncpg.connect(db_url)
    try:
        executed = await conn.fetchval(
            "SELECT executed FROM engine_stats WHERE service='ticker' AND rule_type='Tick'"
        )
    finally:
        await conn.close()
    assert executed is not None and executed > 5


async def test_a_bad_setting_exits_2_naming_the_variable(db_url: str) -> None:
    process = await spawn({"PNAV_DATABASE_URL": db_url, "PNAV_ENGINE_PERIOD_MS": "soon"})
    assert await asyncio.wait_for(process.wait(), 20) == 2
    assert process.stderr is not None
    assert "PNAV_ENGINE_PERIOD_MS='soon' is not a number" in (await process.stderr.read()).decode()


async def test_an_unreachable_database_exits_1_with_a_clear_message(
    zenoh_settings: ZenohSettings,
) -> None:
    env = {
        "PNAV_DATABASE_URL": "postgresql://nobody@127.0.0.1:1/none",
        "PNAV_DB_WAIT_S": "0.5",
        **zenoh_settings.to_env(),
    }
    process = await spawn(env)
    assert await asyncio.wait_for(process.wait(), 30) == 1
    assert process.stderr is not None
    assert "cannot reach Postgres" in (await process.stderr.read()).decode()

"""`pnav up` looks after its embedded Postgres: restarted when it dies, never left behind."""

from __future__ import annotations

import asyncio
import json
import os
import re
import signal
import sys
import time
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

import asyncpg
import psutil
import pytest

from common.postmaster import alive, clean_up, postmaster_pid
from pnav.run.embedded_postgres import free_port

pytestmark = pytest.mark.timeout(120)

PNAV = [sys.executable, "-m", "pnav"]
_RECORD = re.compile(r"^\d{4}-\d\d-\d\dT")  # a log record's first line (not a traceback's)


async def start_up(
    tmp_path: Path, *extra: str, state: Path | None = None
) -> tuple[asyncio.subprocess.Process, dict[str, Any]]:
    state = state or tmp_path / "state"
    stack = state / "stack.json"
    env = {**os.environ, "PNAV_STATE_DIR": str(state)}
    env.pop("PNAV_DATABASE_URL", None)
    up = await asyncio.create_subprocess_exec(
        *PNAV,
        "up",
        "--world",
        "open_room",
        "--rate",
        "5",
        "--zenoh-port",
        str(free_port()),
        "--log-dir",
        str(tmp_path / "logs"),
        "--quiet",
        "--no-dashboard",
        *extra,
        env=env,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.STDOUT,
    )
    deadline = time.monotonic() + 60
    while not (stack.exists() and json.loads(stack.read_text() or "{}").get("pid") == up.pid):
        if up.returncode is not None:
            said = (await up.stdout.read()).decode(errors="replace") if up.stdout else ""
            raise AssertionError(f"pnav up exited {up.returncode} during start-up:\n{said}")
        assert time.monotonic() < deadline, "pnav up never wrote its stack file"
        await asyncio.sleep(0.2)
    return up, json.loads(stack.read_text())


def data_dir_of(url: str) -> Path:
    """The embedded server's data directory: its socket lives there (pgserver)."""
    return Path(parse_qs(urlsplit(url).query)["host"][0])


async def wait_for(check, within: float, what: str):  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + within
    while True:
        value = check()
        if asyncio.iscoroutine(value):
            value = await value
        if value:
            return value
        assert time.monotonic() < deadline, f"timed out after {within} s waiting for {what}"
        await asyncio.sleep(0.2)


async def newest_command(url: str) -> int:
    try:
        conn = await asyncpg.connect(url, timeout=2)
    except (OSError, asyncpg.PostgresError, TimeoutError):
        return -1
    try:
        return int(await conn.fetchval("SELECT coalesce(max(id), 0) FROM command2robot"))
    finally:
        await conn.close()


def records(log_dir: Path) -> dict[str, list[str]]:
    return {p.stem: p.read_text().splitlines() for p in sorted(log_dir.glob("*.log"))}


async def stop(up: asyncio.subprocess.Process) -> str:
    if up.returncode is None:
        up.send_signal(signal.SIGTERM)
        try:
            await asyncio.wait_for(up.wait(), 30)
        except TimeoutError:
            up.kill()
            await up.wait()
    assert up.stdout is not None
    return (await up.stdout.read()).decode()


async def test_a_killed_postmaster_is_restarted_and_the_services_carry_on(
    tmp_path: Path,
) -> None:
    up, info = await start_up(tmp_path)
    try:
        url = info["database_url"]
        data_dir = data_dir_of(url)
        env = {**os.environ, "PNAV_STATE_DIR": str(tmp_path / "state")}
        goal = await asyncio.create_subprocess_exec(*PNAV, "goal", "3", "3", env=env)
        assert await asyncio.wait_for(goal.wait(), 30) == 0
        # the services run and the robot is commanded
        await wait_for(lambda: newest_command(url), 60, "a first command2robot row")
        before = records(tmp_path / "logs")
        old = postmaster_pid(data_dir)
        assert old is not None and alive(old)

        os.kill(old, signal.SIGKILL)
        await wait_for(
            lambda: (pid := postmaster_pid(data_dir)) is not None and pid != old and alive(pid),
            30,
            "a new postmaster",
        )
        restarted_at = await wait_for(lambda: newest_command(url), 30, "Postgres back")
        # commands flow again: rows written after the restart
        await wait_for(lambda: _grew(url, restarted_at), 30, "command2robot rows after the restart")
        # recommendations commit without waiting for their WAL, commands wait for theirs:
        # WAL is written in order, so every recommendation a command cites survived the crash
        commands, missing = await _provenance(url)
        assert commands > 0 and missing == [], missing
        after = records(tmp_path / "logs")
        for service, lines in after.items():
            new = lines[len(before.get(service, [])) :]
            logged = [line for line in new if _RECORD.match(line)]
            print(f"{service}: {len(logged)} log records, {len(new)} lines over the outage")
            # one line when it went, a few while it lasted, one when it came back (and the
            # services' own events: leases lost and re-taken, scenarios ended and restarted)
            assert len(logged) < 25, (service, logged)
            assert len(new) < 40, (service, new)
    finally:
        out = await stop(up)
    assert "embedded Postgres (pid" in out and "embedded Postgres restarted" in out, out
    # the restarted server is stopped with the stack, and its temporary directory removed
    new_pid = postmaster_pid(data_dir)
    assert new_pid is None or not alive(new_pid)
    assert not data_dir.exists()


async def _provenance(url: str) -> tuple[int, list[tuple[int, int]]]:
    """The commands, and each (command, recommendation) pair it cites that does not exist."""
    conn = await asyncpg.connect(url, timeout=5)
    try:
        commands = int(await conn.fetchval("SELECT count(*) FROM command2robot"))
        missing = await conn.fetch(
            """
            SELECT c.id, cited FROM command2robot c,
                   unnest(c.considered_ids || c.recommendation_id) AS cited
             WHERE cited IS NOT NULL
               AND NOT EXISTS (SELECT 1 FROM command_recommendation r WHERE r.id = cited)
            """
        )
    finally:
        await conn.close()
    return commands, [(int(r[0]), int(r[1])) for r in missing]


async def _grew(url: str, than: int) -> bool:
    return await newest_command(url) > than


async def test_a_killed_launcher_leaves_no_postgres_behind(tmp_path: Path) -> None:
    up, info = await start_up(tmp_path)
    data_dir = data_dir_of(info["database_url"])
    try:
        pid = await wait_for(lambda: postmaster_pid(data_dir), 30, "the postmaster")
        assert alive(pid)
        up.kill()
        await up.wait()
        await wait_for(lambda: not alive(pid), 15, "the postmaster to stop")
        await wait_for(lambda: not data_dir.exists(), 15, "the data directory to go")
    finally:
        await stop(up)


async def test_a_kept_data_dir_survives_a_killed_launcher(tmp_path: Path) -> None:
    kept = tmp_path / "pgdata"
    up, _ = await start_up(tmp_path, "--data-dir", str(kept))
    try:
        pid = await wait_for(lambda: postmaster_pid(kept), 30, "the postmaster")
        up.kill()
        await up.wait()
        await wait_for(lambda: not alive(pid), 15, "the postmaster to stop")
        assert (kept / "PG_VERSION").exists()
    finally:
        await stop(up)


async def test_the_next_up_cleans_what_a_stack_without_its_watcher_left(tmp_path: Path) -> None:
    up, info = await start_up(tmp_path)
    data_dir = data_dir_of(info["database_url"])
    try:
        pid = await wait_for(lambda: postmaster_pid(data_dir), 30, "the postmaster")
        watcher = next(
            p
            for p in psutil.Process(up.pid).children()
            if "common.postmaster" in " ".join(p.cmdline())
        )
        watcher.kill()  # no lifeline any more: killing the launcher now leaves Postgres
        await wait_for(lambda: not alive(watcher.pid), 10, "the watcher to die")
        up.kill()
        await up.wait()
        assert alive(pid) and data_dir.exists()
    finally:
        await stop(up)
    again, _ = await start_up(tmp_path / "again", state=tmp_path / "state")
    try:
        await wait_for(lambda: not alive(pid), 15, "the left postmaster to stop")
        await wait_for(lambda: not data_dir.exists(), 15, "the left data directory to go")
    finally:
        out = await stop(again)
        clean_up(data_dir, remove=True)  # whatever happened, leave nothing behind
    assert "cleaned up after a stack that died" in out, out

"""`pnav up` and the commands that drive it, as a user runs them from two terminals."""

from __future__ import annotations

import asyncio
import os
import signal
import sys
import time
from pathlib import Path

import psutil
import pytest

from pnav.run.embedded_postgres import free_port

pytestmark = pytest.mark.timeout(180)

PNAV = [sys.executable, "-m", "pnav"]


async def pnav(*args: str, env: dict[str, str], limit_s: float = 30.0) -> tuple[int, str]:
    process = await asyncio.create_subprocess_exec(
        *PNAV,
        *args,
        env=env,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.STDOUT,
    )
    out, _ = await asyncio.wait_for(process.communicate(), limit_s)
    assert process.returncode is not None
    return process.returncode, out.decode()


async def wait_until_up(env: dict[str, str], up: asyncio.subprocess.Process) -> None:
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        assert up.returncode is None, "pnav up exited during start-up"
        code, out = await pnav("status", "--once", env=env)
        if code == 0 and "r1" in out:
            return
        await asyncio.sleep(0.5)
    raise AssertionError("pnav up never showed robot r1 in `pnav status`")


async def dashboard_shows_r1(port: int) -> None:
    """The dashboard `pnav up` serves answers on the port asked for, and knows the robot."""
    import httpx

    deadline = time.monotonic() + 60
    async with httpx.AsyncClient(timeout=5) as client:
        while True:
            try:
                state = (await client.get(f"http://127.0.0.1:{port}/api/state")).json()
                if "r1" in state["robots"]:
                    return
            except (httpx.TransportError, ValueError, KeyError):
                pass
            assert time.monotonic() < deadline, "the dashboard never showed r1"
            await asyncio.sleep(0.5)


async def test_up_goal_strategy_cancel_status_down(tmp_path: Path) -> None:
    env = {**os.environ, "PNAV_STATE_DIR": str(tmp_path / "state")}
    env.pop("PNAV_DATABASE_URL", None)
    http_port = free_port()
    up = await asyncio.create_subprocess_exec(
        *PNAV,
        "up",
        "--world",
        "open_room",
        # real time, and a goal 4.2 m away: the goal must still be live for `status` and
        # `cancel` after four CLI runs (at rate 5 a 2.8 m goal was reached in about 3 s of
        # wall time, a race the CLI won only while the machine was slow)
        "--rate",
        "1",
        "--zenoh-port",
        str(free_port()),
        "--log-dir",
        str(tmp_path / "logs"),
        "--http-port",
        str(http_port),
        "--quiet",
        # one process per service: a crash of the planner alone (the composed host's crash
        # and restart: tests/contract/host)
        "--processes",
        "separate",
        env=env,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.STDOUT,
    )
    try:
        await wait_until_up(env, up)
        children = psutil.Process(up.pid).children(recursive=True)
        # sim, bridge, strategy, planner, controller, decision, dashboard
        assert len(children) >= 7
        await dashboard_shows_r1(http_port)

        code, out = await pnav("goal", "4.0", "4.0", env=env)
        assert code == 0 and "goal 1 set to (4.0, 4.0)" in out, out

        code, out = await pnav("strategy", "GOTO_DIRECT", env=env)
        assert code == 0 and "r1: accepted" in out, out
        code, out = await pnav("strategy", "NO_SUCH_THING", env=env)
        assert code == 2 and "unknown strategy 'NO_SUCH_THING'" in out, out

        code, out = await pnav("status", "--once", env=env)
        assert code == 0 and "GOTO_DIRECT" in out and "(4.0,4.0)" in out, out

        code, out = await pnav("cancel", env=env)
        assert code == 0 and "goal 1 cancelled" in out, out

        # a process started by hand joins as a service: its role and Zenoh user
        code, out = await pnav("env", "controller", env=env)
        assert code == 0 and "export PNAV_ZENOH_USER=controller" in out, out
        assert "pnav_controller" in out and "PNAV_ZENOH_PASSWORD=" in out, out
        code, out = await pnav("env", "nobody", env=env)
        assert code == 2 and "no role 'nobody'" in out, out
        code, out = await pnav("goal", "1", "1", "--robot", "nobody", env=env)
        assert code == 2 and "no robot 'nobody'" in out, out

        # a crashed service is restarted, and says so
        planner = next(p for p in children if "services.planner" in " ".join(p.cmdline()))
        planner.send_signal(signal.SIGKILL)
        log = tmp_path / "logs"
        deadline = time.monotonic() + 30
        while not any(
            "services.planner" in " ".join(p.cmdline())
            for p in psutil.Process(up.pid).children(recursive=True)
            if p.pid != planner.pid and p.is_running()
        ):
            assert time.monotonic() < deadline, "the planner was not restarted"
            await asyncio.sleep(0.2)

        code, out = await pnav("down", env=env)
        assert code == 0 and "stopped" in out, out
        assert await asyncio.wait_for(up.wait(), 30) == 0
        assert up.stdout is not None
        up_log = (await up.stdout.read()).decode()
        assert "planner exited with code -9" in up_log and "restarting" in up_log, up_log
        assert f"dashboard: http://127.0.0.1:{http_port}/" in up_log, up_log
        assert (log / "planner.log").exists()
        for child in children:
            assert not child.is_running() or child.status() == psutil.STATUS_ZOMBIE
        code, out = await pnav("status", "--once", env=env)
        assert code == 2 and "no running stack" in out
    finally:
        if up.returncode is None:
            up.kill()
            await up.wait()


async def test_commands_without_a_stack_say_how_to_start_one(tmp_path: Path) -> None:
    env = {**os.environ, "PNAV_STATE_DIR": str(tmp_path)}
    env.pop("PNAV_DATABASE_URL", None)
    code, out = await pnav("goal", "1", "1", env=env)
    assert code == 2 and "pnav up" in out
    code, out = await pnav("down", env=env)
    assert code == 0 and "no running stack" in out

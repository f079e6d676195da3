"""``python -m services.bridge`` as its own process: configured from env, stopped by SIGTERM."""

from __future__ import annotations

import asyncio
import os
import signal
import sys

import asyncpg
import pytest

from common.config import ZenohSettings
from common.contract import keys
from pnav._testing import eventually
from tests.contract.bridge.conftest import SETTLE_S, FakeSim
from tests.unit.bridge import payloads

pytestmark = pytest.mark.timeout(60)


async def test_the_bridge_process_bridges_and_stops_cleanly_on_sigterm(
    db_url: str, zenoh_settings: ZenohSettings, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    sim.serve_world(payloads.world())
    cmd_vel = sim.listen(keys.robot_watch(keys.CMD_VEL))
    odom_notes = sim.listen(keys.notify_watch(keys.ODOMETRY))
    await asyncio.sleep(SETTLE_S)
    env = {
        **os.environ,
        "PNAV_DATABASE_URL": db_url,
        **zenoh_settings.to_env(),
        "PNAV_INSTANCE": "bridge-proc",
    }
    child = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "services.bridge", env=env, stderr=asyncio.subprocess.PIPE
    )
    try:
        await eventually(
            lambda: conn.fetchval("SELECT count(*) FROM robot"), within=20, what="the robot row"
        )
        await asyncio.sleep(SETTLE_S)  # its sensor subscriptions reach the router
        sim.sensor("r1", keys.ODOM, payloads.odom(seq=1))
        _, note = await odom_notes.next(within=10)
        assert await conn.fetchval("SELECT seq FROM odometry WHERE id = $1", note["id"]) == 1

        row_id = await conn.fetchval(
            "INSERT INTO command2robot (robot_id, stamp, linear_mps, angular_rps)"
            " VALUES ('r1', 0, 0.1, 0.2) RETURNING id"
        )
        sim.notifier.notify(keys.COMMAND2ROBOT, "r1", row_id)
        _, body = await cmd_vel.next(within=10)
        assert (body["linear"], body["angular"], body["command_id"]) == (0.1, 0.2, row_id)

        child.send_signal(signal.SIGTERM)
        assert await asyncio.wait_for(child.wait(), 20) == 0
        _, stop = await cmd_vel.next(within=5)
        assert (stop["linear"], stop["angular"], stop["command_id"]) == (0.0, 0.0, None)
        assert child.stderr is not None
        log = (await child.stderr.read()).decode()
        assert "bridge started" in log and "stop sent on shutdown" in log, log
        assert "Traceback" not in log, log
    finally:
        if child.returncode is None:
            child.kill()
            await child.wait()


async def test_a_missing_database_url_exits_with_a_usage_error() -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("PNAV_")}
    child = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "services.bridge", env=env, stderr=asyncio.subprocess.PIPE
    )
    _, err = await asyncio.wait_for(child.communicate(), 30)
    assert child.returncode == 2
    assert b"PNAV_DATABASE_URL" in err

"""The sim and the bridge alone, driven as a foreign client would: plain SQL only.

No scenario service runs. The test inserts command2robot rows with plain SQL (no
notification: the bridge's period fallback must pick them up) and reads odometry rows back.
"""

from __future__ import annotations

import asyncio
import math

import asyncpg
import pytest

from pnav._testing import eventually
from pnav.run.launcher import launched
from pnav.run.stack_options import StackOptions
from services.sim.robot import BURGER

pytestmark = pytest.mark.timeout(120)

INSERT = (
    "INSERT INTO command2robot (robot_id, stamp, linear_mps, angular_rps, reason) "
    "VALUES ('r1', $1, $2, $3, 'contract test')"
)
NEWEST = "SELECT stamp, x, y, yaw, linear_mps, angular_rps FROM odometry ORDER BY id DESC LIMIT 1"


async def drive(conn: asyncpg.Connection, linear: float, angular: float, sim_s: float) -> None:
    """Keep a command fresh (a new row every 0.1 s of sim time) for ``sim_s`` of sim time."""
    start = (await conn.fetchrow(NEWEST))["stamp"]
    while True:
        now = (await conn.fetchrow(NEWEST))["stamp"]
        if now >= start + sim_s:
            return
        await conn.execute(INSERT, now, linear, angular)
        await asyncio.sleep(0.05)


async def test_commands_move_and_turn_the_robot_and_the_watchdog_stops_it() -> None:
    options = StackOptions(world="open_room", rate="1", zenoh_port=None, services=("sim", "bridge"))
    async with launched(options) as stack:
        conn = await asyncpg.connect(stack.local.database_url)
        try:
            await eventually(lambda: conn.fetchrow(NEWEST), within=30, what="odometry rows")
            before = await conn.fetchrow(NEWEST)
            assert before["yaw"] == pytest.approx(0.0, abs=0.01)  # open_room: r1 faces +x

            await drive(conn, 0.2, 0.0, sim_s=2.0)
            moved = await conn.fetchrow(NEWEST)
            assert moved["x"] - before["x"] == pytest.approx(0.4, abs=0.1)  # forward is +x
            assert moved["y"] == pytest.approx(before["y"], abs=0.02)
            assert moved["linear_mps"] == pytest.approx(0.2, abs=0.01)

            await drive(conn, 5.0, 1.0, sim_s=1.5)  # 5 m/s asked: clamped to 0.22
            turned = await conn.fetchrow(NEWEST)
            assert turned["linear_mps"] == pytest.approx(0.22, abs=0.01)
            assert turned["angular_rps"] == pytest.approx(1.0, abs=0.01)
            turn = math.remainder(turned["yaw"] - moved["yaw"], math.tau)
            # positive angular: counter-clockwise; 1 rad/s for 1.5 s less what the ramp up to
            # it at the Burger's angular acceleration limit loses (half the ramp's time)
            ramp_s = 1.0 / BURGER.max_angular_accel_rps2
            assert turn == pytest.approx(1.5 - ramp_s / 2, abs=0.25)

            # no more commands: the watchdog stops the robot 0.5 s of sim time later
            silent_from = turned["stamp"]
            stopped = await eventually(
                lambda: _stopped(conn), within=10, what="the watchdog's stop"
            )
            assert silent_from + 0.4 <= stopped["stamp"] <= silent_from + 1.5
        finally:
            await conn.close()


async def _stopped(conn: asyncpg.Connection) -> asyncpg.Record | None:
    row = await conn.fetchrow(NEWEST)
    return row if row["linear_mps"] == 0.0 and row["angular_rps"] == 0.0 else None

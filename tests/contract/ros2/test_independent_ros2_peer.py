"""The stack drives a TurtleBot3 played by an independent ROS 2 client (zenoh-ros2-sdk, not
the project's rmw_zenoh code) to a goal sent as RViz sends it, as `pnav up --no-sim` runs
it: no pybullet sim; the bridge gives the stack its clock in ROS time (``clock: ros``), and
the sim's process only announces the world (``--world-only``) for the robots' rows."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import asyncpg
import pytest

from pnav._testing import eventually
from pnav.run.launcher import launched, resolve_world
from services.sim.world_spec import load_world
from tests.contract.ros2.turtlebot3_peer import TurtleBot3, peer_stack_options

pytestmark = [pytest.mark.timeout(240), pytest.mark.slow]

GOAL = (2.0, 1.5)
GOAL_SQL = "SELECT status, reason FROM goal WHERE robot_id = 'r1' ORDER BY id DESC LIMIT 1"


async def test_the_stack_drives_an_independent_ros2_turtlebot3_to_an_rviz_goal(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    options = peer_stack_options(tmp_path)
    world = load_world(resolve_world("open_room"))
    start = world.message()["robots"][0]
    async with launched(options) as stack:
        local = stack.local
        # the robot joins the stack's router as the sim does
        sim_auth = local.zenoh_for("sim")
        if sim_auth.user:
            auth = json.dumps({"user": sim_auth.user, "password": sim_auth.password})
            monkeypatch.setenv("ZENOH_CONFIG_OVERRIDE", f"transport/auth/usrpwd={auth}")
        port = int(local.zenoh.connect[0].rsplit(":", 1)[1])
        robot = await asyncio.to_thread(TurtleBot3, port, start["x"], start["y"], start["yaw"])
        robot.start()
        conn = await asyncpg.connect(local.database_url)
        try:
            await eventually(
                lambda: conn.fetchval("SELECT count(*) FROM odometry"),
                within=60,
                interval=0.5,
                what="the robot's odometry as rows",
            )
            # RViz's 2D Goal Pose on /goal_pose, through the stack's rviz process
            for _ in range(30):
                robot.send_goal(*GOAL)
                if await conn.fetchval("SELECT count(*) FROM goal"):
                    break
                await asyncio.sleep(1.0)
            reached = await eventually(
                lambda: _reached(conn), within=150, interval=0.5, what="the goal reached"
            )
            assert reached
            assert robot.commands > 0
            distance = ((robot.x - GOAL[0]) ** 2 + (robot.y - GOAL[1]) ** 2) ** 0.5
            assert distance < 0.3
            # the rows are stamped in ROS time: the system clock
            newest = await conn.fetchval("SELECT max(stamp) FROM odometry")
            assert newest > 1.0e9
        finally:
            robot.close()
            await conn.close()


async def _reached(conn: asyncpg.Connection) -> bool:
    row = await conn.fetchrow(GOAL_SQL)
    if row is not None and row["status"] == "failed":
        raise AssertionError(f"goal failed: {row['reason']}")
    return row is not None and row["status"] == "reached"

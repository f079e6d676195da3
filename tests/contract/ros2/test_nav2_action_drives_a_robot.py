"""The whole stack, as `pnav up --no-sim --robot-link ros2` runs it, driving a TurtleBot3
played by an independent ROS 2 client (zenoh-ros2-sdk) to a goal sent as Nav2's Simple
Commander sends one: a NavigateToPose action goal from a client written from the wire format
(nav2_client.py), its feedback while the robot drives, SUCCEEDED when it is there."""

from __future__ import annotations

import asyncio
import json
import math
import os
from pathlib import Path

import asyncpg
import pytest

from common import bus
from pnav._testing import eventually
from pnav.run.launcher import launched, resolve_world
from services.sim.world_spec import load_world
from tests.contract.ros2.nav2_client import NavClient
from tests.contract.ros2.turtlebot3_peer import TurtleBot3, peer_stack_options

pytestmark = [pytest.mark.timeout(240), pytest.mark.slow]

GOAL = (2.0, 1.5, math.pi / 2)
SUCCEEDED = 4


async def test_a_navigate_to_pose_goal_drives_the_robot_there(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    options = peer_stack_options(tmp_path)
    start = load_world(resolve_world("open_room")).message()["robots"][0]
    async with launched(options) as stack:
        local = stack.local
        sim_auth = local.zenoh_for("sim")  # the robot joins the stack's router as the sim does
        if sim_auth.user:
            auth = json.dumps({"user": sim_auth.user, "password": sim_auth.password})
            monkeypatch.setenv("ZENOH_CONFIG_OVERRIDE", f"transport/auth/usrpwd={auth}")
        port = int(local.zenoh.connect[0].rsplit(":", 1)[1])
        robot = await asyncio.to_thread(TurtleBot3, port, start["x"], start["y"], start["yaw"])
        robot.start()
        # the navigation client is a person's tool: the user identity
        session = await asyncio.to_thread(bus.open_session, local.zenoh_for("user"))
        # robot r1 under its default namespace, /r1 (BasicNavigator(namespace="r1"))
        client = NavClient(session, "/r1/navigate_to_pose")
        conn = await asyncpg.connect(local.database_url)
        try:
            await eventually(
                lambda: conn.fetchval("SELECT count(*) FROM odometry"),
                within=60,
                interval=0.5,
                what="the robot's odometry as rows",
            )
            await eventually(
                lambda: "SS /r1/navigate_to_pose/_action/send_goal" in client.server_tokens(),
                within=60,
                interval=0.5,
                what="the action server",
            )
            goal_id = os.urandom(16)
            reply = await asyncio.to_thread(client.send_goal, goal_id, client.to_pose_goal(*GOAL))
            assert reply.accepted
            result = await asyncio.to_thread(client.get_result, goal_id, 180.0)
            assert (result.status, result.result.error_code) == (SUCCEEDED, 0), result
            distance = math.hypot(robot.x - GOAL[0], robot.y - GOAL[1])
            assert distance < 0.3
            feedback = client.feedback_of(goal_id)
            assert feedback, "no feedback while driving"
            # the distance left shrank as the robot drove
            assert feedback[-1].distance_remaining < feedback[0].distance_remaining
            row = await conn.fetchrow("SELECT status, yaw FROM goal ORDER BY id DESC LIMIT 1")
            assert row["status"] == "reached" and row["yaw"] == pytest.approx(GOAL[2])
        finally:
            client.close()
            session.close()
            robot.close()
            await conn.close()

"""The generic action server (common/ros2action.py) with an owner of the test's own, on a real
Zenoh router, driven by the wire-format client: a cancel that arrives while the owner is
still deciding on the goal reaches the owner once it accepts."""

from __future__ import annotations

import asyncio
import os
from collections.abc import AsyncIterator

import pytest
import zenoh

from common import bus, ros2types
from common.config import ZenohSettings
from common.ros2action import CANCELED, CANCELING, ActionServer
from common.ros2interfaces import NAVIGATE_TO_POSE
from common.ros2node import Ros2Node
from pnav._testing import eventually
from tests.contract.ros2.nav2_client import NavClient

pytestmark = pytest.mark.slow


@pytest.fixture
async def sessions(zenoh_settings: ZenohSettings) -> AsyncIterator[list[zenoh.Session]]:
    opened = [await asyncio.to_thread(bus.open_session, zenoh_settings) for _ in range(2)]
    try:
        yield opened
    finally:
        for session in opened:
            session.close()


async def test_a_cancel_while_the_owner_decides_reaches_it_once_accepted(
    sessions: list[zenoh.Session],
) -> None:
    decide = asyncio.Event()
    cancelled: list[bytes] = []
    node = Ros2Node(sessions[0], 0, "owner")

    async def on_goal(goal_id: bytes, goal: object) -> bool:
        await decide.wait()
        return True

    async def on_cancel(goal_id: bytes) -> None:
        cancelled.append(goal_id)
        result = ros2types.default(f"{NAVIGATE_TO_POSE}_Result")
        server.finish(goal_id, CANCELED, result)

    server = ActionServer(
        node, "navigate_to_pose", NAVIGATE_TO_POSE, on_goal=on_goal, on_cancel=on_cancel
    )
    client = NavClient(sessions[1], "/navigate_to_pose")
    try:
        await eventually(
            lambda: "SS /navigate_to_pose/_action/cancel_goal" in client.server_tokens(),
            what="the server",
        )
        goal_id = os.urandom(16)
        sent = asyncio.create_task(
            asyncio.to_thread(client.send_goal, goal_id, client.to_pose_goal(1.0, 1.0))
        )
        await eventually(lambda: goal_id in server.goals, what="the goal handed to the owner")
        reply = await asyncio.to_thread(client.cancel, goal_id)
        assert reply.return_code == 0 and server.goals[goal_id].status == CANCELING
        assert cancelled == []  # the owner has not accepted it yet: nothing to cancel for it
        decide.set()
        assert (await sent).accepted
        result = await asyncio.to_thread(client.get_result, goal_id)
        assert result.status == CANCELED and cancelled == [goal_id]
    finally:
        client.close()
        await server.close()
        node.close()

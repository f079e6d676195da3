"""Nav2's NavigateToPose and NavigateThroughPoses served by the rviz process (pnav/ros2/
nav2actions.py over common/ros2action.py), driven by an action client written from the wire
format alone (nav2_client.py), on a real Zenoh router and Postgres: the goal becomes the
robot's goal row, feedback comes from the rows, the result from the row's end; cancel,
preemption and refused goals."""

from __future__ import annotations

import asyncio
import math
import os
from collections.abc import AsyncIterator
from dataclasses import replace
from pathlib import Path

import asyncpg
import pytest
import zenoh

from common import bus
from common.config import ServiceConfig, ZenohSettings
from common.contract.grants import USER
from common.robotlink import RobotLinkSettings, RobotTopics
from common.runtime import Runtime
from pnav._testing import as_service_role, eventually
from pnav.ros2.rviz import RvizLink
from pnav.run.embedded_postgres import free_port
from pnav.run.local_stack import BusCredentials
from tests.contract.ros2.nav2_client import NavClient, pose

pytestmark = pytest.mark.slow

# action_msgs/msg/GoalStatus
UNKNOWN, EXECUTING, SUCCEEDED, CANCELED, ABORTED = 0, 2, 4, 5, 6


@pytest.fixture
async def rviz(db_url: str, zenoh_settings: ZenohSettings) -> AsyncIterator[RvizLink]:
    async for link in _serve(db_url, zenoh_settings):
        yield link


async def _serve(db_url: str, zenoh_settings: ZenohSettings) -> AsyncIterator[RvizLink]:
    conn = await asyncpg.connect(db_url)
    try:
        await conn.execute("INSERT INTO robot (robot_id) VALUES ('r1')")
    finally:
        await conn.close()
    url = await as_service_role(db_url, "user")  # people's grants, exactly
    runtime = await Runtime.open(
        ServiceConfig(service="rviz", database_url=url, zenoh=zenoh_settings)
    )
    ros = await asyncio.to_thread(bus.open_session, zenoh_settings)
    link = RobotLinkSettings(
        link="ros2", robots={"r1": RobotTopics(namespace="", explicit_namespace=True)}
    )
    rviz = RvizLink(runtime, link, ros)
    await rviz.start()
    try:
        yield rviz
    finally:
        await rviz.close()
        ros.close()
        await runtime.close()


@pytest.fixture
async def client_session(zenoh_settings: ZenohSettings) -> AsyncIterator[zenoh.Session]:
    session = await asyncio.to_thread(bus.open_session, zenoh_settings)
    try:
        yield session
    finally:
        session.close()


async def _sql(db_url: str, sql: str, *args: object) -> list[asyncpg.Record]:
    conn = await asyncpg.connect(db_url)
    try:
        return list(await conn.fetch(sql, *args))
    finally:
        await conn.close()


async def _ready(client: NavClient) -> None:
    """As rclpy's wait_for_server: the three services and two topics are in the graph."""
    base = "/" + client.action + "/_action/"
    wanted = {f"SS {base}send_goal", f"SS {base}get_result", f"SS {base}cancel_goal"}
    wanted |= {f"MP {base}feedback", f"MP {base}status"}
    await eventually(lambda: wanted <= client.server_tokens(), what="the action server")


async def test_a_goal_gets_feedback_and_succeeds(
    rviz: RvizLink, client_session: zenoh.Session, db_url: str
) -> None:
    client = NavClient(client_session, "/navigate_to_pose")
    await _ready(client)
    # Simple Commander's waitUntilNav2Active(localizer=...) asks the navigator's state
    assert await asyncio.to_thread(client.navigator_state) == "active"
    goal_id = os.urandom(16)
    reply = await asyncio.to_thread(client.send_goal, goal_id, client.to_pose_goal(3.0, 4.0, 1.0))
    assert reply.accepted
    [row] = await _sql(db_url, "SELECT id, robot_id, x, y, yaw, status FROM goal")
    assert (row["robot_id"], row["x"], row["y"], row["status"]) == ("r1", 3.0, 4.0, "active")
    assert row["yaw"] == pytest.approx(1.0)
    # the result is asked for at once, as rclpy does, and answered when the goal ends
    result = asyncio.create_task(asyncio.to_thread(client.get_result, goal_id))
    # the robot at (0, 0) with a path planned through (3, 0) to the goal: 3 + 4 m to go
    await _sql(
        db_url,
        "INSERT INTO odometry (robot_id, stamp, x, y, yaw, linear_mps, angular_rps) "
        "VALUES ('r1', 5.0, 0, 0, 0, 0.5, 0)",
    )
    await _sql(
        db_url,
        "INSERT INTO planned_path (robot_id, stamp, goal_id, target, target_x, target_y, xs, "
        "ys, length_m) VALUES ('r1', 5.0, $1, 'goal', 3, 4, '{0,3,3}', '{0,0,4}', 7)",
        row["id"],
    )
    feedback = await eventually(lambda: client.feedback_of(goal_id), what="feedback")
    first = feedback[-1]
    assert first.distance_remaining == pytest.approx(7.0)
    assert first.estimated_time_remaining.sec == 14  # 7 m at 0.5 m/s
    assert first.current_pose.header.frame_id == "map"
    assert (first.current_pose.pose.position.x, first.current_pose.pose.position.y) == (0, 0)
    assert client.status_of(goal_id) == EXECUTING
    assert not result.done()
    # the planner's word: reached
    await _sql(db_url, "UPDATE goal SET status = 'reached' WHERE id = $1", row["id"])
    done = await asyncio.wait_for(result, 30)
    assert (done.status, done.result.error_code) == (SUCCEEDED, 0)
    await eventually(lambda: client.status_of(goal_id) == SUCCEEDED, what="the status")
    # asked again later, and for a goal never sent
    again = await asyncio.to_thread(client.get_result, goal_id)
    assert again.status == SUCCEEDED
    unknown = await asyncio.to_thread(client.get_result, os.urandom(16))
    assert unknown.status == UNKNOWN
    client.close()


async def test_cancel_and_preemption(
    rviz: RvizLink, client_session: zenoh.Session, db_url: str
) -> None:
    client = NavClient(client_session, "/navigate_to_pose")
    await _ready(client)
    first, second = os.urandom(16), os.urandom(16)
    assert (await asyncio.to_thread(client.send_goal, first, client.to_pose_goal(1, 1))).accepted
    # a newer goal preempts the first: Nav2 aborts the goal it replaces
    assert (await asyncio.to_thread(client.send_goal, second, client.to_pose_goal(2, 2))).accepted
    aborted = await asyncio.to_thread(client.get_result, first)
    assert (aborted.status, aborted.result.error_code) == (ABORTED, 9000)
    assert "preempted" in aborted.result.error_msg
    # the second is cancelled by its id
    reply = await asyncio.to_thread(client.cancel, second)
    assert reply.return_code == 0
    assert [bytes(g.goal_id.uuid.tobytes()) for g in reply.goals_canceling] == [second]
    cancelled = await asyncio.to_thread(client.get_result, second)
    assert cancelled.status == CANCELED
    rows = await _sql(db_url, "SELECT x, status FROM goal ORDER BY id")
    assert [tuple(r) for r in rows] == [(1.0, "superseded"), (2.0, "cancelled")]
    # a goal someone else sets (pnav goal, the dashboard, RViz) supersedes an action's goal
    third = os.urandom(16)
    assert (await asyncio.to_thread(client.send_goal, third, client.to_pose_goal(3, 3))).accepted
    await _sql(
        db_url,
        "UPDATE goal SET status = 'superseded', reason = 'replaced by a new goal' "
        "WHERE robot_id = 'r1' AND status = 'active'",
    )
    await _sql(db_url, "INSERT INTO goal (robot_id, x, y) VALUES ('r1', 4, 4)")
    superseded = await asyncio.to_thread(client.get_result, third)
    assert (superseded.status, superseded.result.error_code) == (ABORTED, 9000)
    assert superseded.result.error_msg == "superseded: replaced by a new goal"
    # cancelling an ended goal, and one never sent: the codes rcl_action answers
    assert (await asyncio.to_thread(client.cancel, second)).return_code == 3
    assert (await asyncio.to_thread(client.cancel, os.urandom(16))).return_code == 2
    client.close()


async def test_a_route_through_poses_reports_the_poses_left_and_fails_with_the_reason(
    rviz: RvizLink, client_session: zenoh.Session, db_url: str
) -> None:
    client = NavClient(client_session, "/navigate_through_poses")
    await _ready(client)
    goal_id = os.urandom(16)
    poses = [pose(1.0, 0.0, 0.3), pose(2.0, 0.0), pose(2.0, 2.0, math.pi / 2)]
    reply = await asyncio.to_thread(client.send_goal, goal_id, client.through_goal(poses))
    assert reply.accepted
    [goal] = await _sql(db_url, "SELECT id, x, y, yaw FROM goal")
    assert (goal["x"], goal["y"]) == (2.0, 2.0) and goal["yaw"] == pytest.approx(math.pi / 2)
    waypoints = await _sql(
        db_url,
        "SELECT seq, x, y, yaw FROM goal_waypoint WHERE goal_id = $1 ORDER BY seq",
        goal["id"],
    )
    # driven through: a waypoint's heading would halt the robot there
    assert [tuple(w) for w in waypoints] == [(1, 1.0, 0.0, None), (2, 2.0, 0.0, None)]
    await _sql(
        db_url,
        "INSERT INTO odometry (robot_id, stamp, x, y, yaw, linear_mps, angular_rps) "
        "VALUES ('r1', 5.0, 0, 0, 0, 0, 0)",
    )
    await eventually(
        lambda: any(f.number_of_poses_remaining == 3 for f in client.feedback_of(goal_id)),
        what="three poses left",
    )
    await _sql(
        db_url,
        "UPDATE goal_waypoint SET status = 'reached' WHERE goal_id = $1 AND seq = 1",
        goal["id"],
    )
    latest = await eventually(
        lambda: [f for f in client.feedback_of(goal_id) if f.number_of_poses_remaining == 2],
        what="two poses left",
    )
    # no path yet: straight from the robot through (2, 0) to (2, 2)
    assert latest[-1].distance_remaining == pytest.approx(4.0)
    await _sql(
        db_url,
        "UPDATE goal SET status = 'failed', reason = 'waypoint 2 unreachable' WHERE id = $1",
        goal["id"],
    )
    failed = await asyncio.to_thread(client.get_result, goal_id)
    assert (failed.status, failed.result.error_code) == (ABORTED, 9000)
    assert "waypoint 2 unreachable" in failed.result.error_msg
    client.close()


async def test_bad_goals_are_refused_with_a_reason(
    rviz: RvizLink, client_session: zenoh.Session, db_url: str
) -> None:
    to_pose = NavClient(client_session, "/navigate_to_pose")
    through = NavClient(client_session, "/navigate_through_poses")
    await _ready(to_pose)
    await _ready(through)

    async def refused(client: NavClient, goal: object) -> bool:
        reply = await asyncio.to_thread(client.send_goal, os.urandom(16), goal)
        return not reply.accepted

    assert await refused(to_pose, to_pose.to_pose_goal(math.nan, 1.0))
    assert await refused(to_pose, to_pose.to_pose_goal(1.0, 1.0, frame="odom"))
    assert await refused(to_pose, to_pose.to_pose_goal(1e9, 1.0))
    assert await refused(through, through.through_goal([]))
    assert await refused(through, through.through_goal([pose(1, 1), pose(1, 2, frame="odom")]))
    too_many = [pose(float(i % 50), 1.0) for i in range(10_000)]
    assert await refused(through, through.through_goal(too_many))
    nav = rviz.nav
    assert nav.refused == {"out_of_range": 3, "frame": 2, "no_poses": 1}
    # bytes that are not a request: answered (not accepted), counted by the server
    garbage = await asyncio.to_thread(to_pose.call, "send_goal", "SendGoal", b"\x00\x01\x00")
    assert garbage[4] == 0  # CDR header, then accepted = false
    assert sum(s.refused["bad_cdr"] for s in nav.servers["r1"]) == 1
    assert await _sql(db_url, "SELECT id FROM goal") == []
    to_pose.close()
    through.close()


async def test_through_the_local_stacks_router_with_its_access_control(
    db_url: str, tmp_path: Path
) -> None:
    """As ``pnav up --robot-link ros2`` runs it: the router checks every session's user and
    lets the ROS 2 identities (``user`` among them) serve and call services in the domain;
    an identity that may not speak ROS 2 gets no answer."""
    creds = BusCredentials.create(tmp_path)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = bus.start_router((endpoint,), str(creds.users_file), ros_domains=(0,))
    base = ZenohSettings(mode="client", connect=(endpoint,))
    person = replace(base, user=USER, password=creds.passwords[USER])
    stranger = replace(base, user="strategy", password=creds.passwords["strategy"])
    try:
        async for _link in _serve(db_url, person):
            session = await asyncio.to_thread(bus.open_session, person)
            other = await asyncio.to_thread(bus.open_session, stranger)
            try:
                client = NavClient(session, "/navigate_to_pose")
                await _ready(client)
                goal_id = os.urandom(16)
                goal = client.to_pose_goal(1.0, 2.0)
                assert (await asyncio.to_thread(client.send_goal, goal_id, goal)).accepted
                assert (await asyncio.to_thread(client.cancel, goal_id)).return_code == 0
                assert (await asyncio.to_thread(client.get_result, goal_id)).status == CANCELED
                denied = NavClient(other, "/navigate_to_pose")
                with pytest.raises(AssertionError, match="no reply"):
                    await asyncio.to_thread(
                        denied.call_key, client.key("send_goal", "SendGoal"), b"", 2.0
                    )
                client.close()
                denied.close()
            finally:
                session.close()
                other.close()
    finally:
        router.close()

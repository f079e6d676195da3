"""RViz on the ROS 2 graph (pnav/ros2/rviz.py, acting for people): a 2D Goal Pose on
``/goal_pose`` or ``<ns>/goal_pose`` becomes the robot's goal row as ``pnav goal`` writes it;
each planned_path row goes out as a nav_msgs/Path on ``<ns>/plan``."""

from __future__ import annotations

import asyncio
import math
from collections.abc import AsyncIterator
from typing import Any

import asyncpg
import pytest
import zenoh

from common import bus, ros2types
from common.config import ServiceConfig, ZenohSettings
from common.robotlink import RobotLinkSettings, RobotTopics
from common.ros2node import Ros2Node
from common.runtime import Runtime
from pnav._testing import as_service_role, eventually
from pnav.ros2.rviz import RvizLink
from tests.contract.bridge.conftest import SETTLE_S

pytestmark = pytest.mark.slow

GOALS = "SELECT robot_id, x, y, tolerance_m, status FROM goal ORDER BY id"
HEADINGS = "SELECT yaw, yaw_tolerance_rad FROM goal ORDER BY id"


def goal_pose(x: float, y: float, frame: str = "map", orientation: Any = None) -> Any:
    point = ros2types.message("geometry_msgs/msg/Point", x=x, y=y, z=0.0)
    pose = ros2types.message(
        "geometry_msgs/msg/Pose",
        position=point,
        orientation=ros2types.quaternion(1.0) if orientation is None else orientation,
    )
    return ros2types.message(ros2types.POSE_STAMPED, header=ros2types.header(3.0, frame), pose=pose)


async def _link(
    db_url: str, zenoh_settings: ZenohSettings, robots: tuple[str, ...], link: RobotLinkSettings
) -> AsyncIterator[RvizLink]:
    conn = await asyncpg.connect(db_url)
    try:
        for robot in robots:  # the bridge's rows, from the world
            await conn.execute("INSERT INTO robot (robot_id) VALUES ($1)", robot)
    finally:
        await conn.close()
    url = await as_service_role(db_url, "user")  # people's grants, exactly
    config = ServiceConfig(service="rviz", database_url=url, zenoh=zenoh_settings)
    runtime = await Runtime.open(config)
    ros = await asyncio.to_thread(bus.open_session, zenoh_settings)
    rviz = RvizLink(runtime, link, ros)
    await rviz.start()
    try:
        yield rviz
    finally:
        await rviz.close()
        ros.close()
        await runtime.close()


@pytest.fixture
async def one_robot(db_url: str, zenoh_settings: ZenohSettings) -> AsyncIterator[RvizLink]:
    link = RobotLinkSettings(
        link="ros2", robots={"r1": RobotTopics(namespace="", explicit_namespace=True)}
    )
    async for rviz in _link(db_url, zenoh_settings, ("r1",), link):
        yield rviz


@pytest.fixture
async def two_robots(db_url: str, zenoh_settings: ZenohSettings) -> AsyncIterator[RvizLink]:
    async for rviz in _link(db_url, zenoh_settings, ("r1", "r2"), RobotLinkSettings(link="ros2")):
        yield rviz


async def _fetch(db_url: str, sql: str) -> list[asyncpg.Record]:
    conn = await asyncpg.connect(db_url)
    try:
        return list(await conn.fetch(sql))
    finally:
        await conn.close()


async def _goals(db_url: str) -> list[asyncpg.Record]:
    return await _fetch(db_url, GOALS)


async def test_rviz_goal_pose_becomes_the_robots_goal_row(
    one_robot: RvizLink, ros_session: zenoh.Session, db_url: str
) -> None:
    rviz = Ros2Node(ros_session, 0, "rviz2")
    publisher = rviz.publisher("/goal_pose", ros2types.POSE_STAMPED)
    await asyncio.sleep(SETTLE_S)
    publisher.put(goal_pose(1.5, -0.75), reliable=True)
    await eventually(lambda: one_robot.goals_set == 1, what="a goal")
    # a client that sets only a position leaves the quaternion all zero: any heading
    unset = ros2types.message("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=0.0, w=0.0)
    publisher.put(goal_pose(2.0, 1.0, orientation=unset), reliable=True)  # supersedes it
    await eventually(lambda: one_robot.goals_set == 2, what="a second goal")
    rows = await _goals(db_url)
    assert [tuple(r) for r in rows] == [
        ("r1", 1.5, -0.75, 0.15, "superseded"),
        ("r1", 2.0, 1.0, 0.15, "active"),
    ]
    # RViz's arrow is the goal's heading, with the contract's default tolerance
    (arrow, yaw_tol), (none, none_tol) = [tuple(r) for r in await _fetch(db_url, HEADINGS)]
    assert arrow == pytest.approx(1.0) and yaw_tol == pytest.approx(0.1)
    assert none is None and none_tol is None
    # not in the map frame, beyond the contract's bounds, a heading that is no number, not a
    # PoseStamped: refused
    publisher.put(goal_pose(1.0, 1.0, frame="odom"), reliable=True)
    publisher.put(goal_pose(math.inf, 1.0), reliable=True)
    nan = ros2types.message("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=math.nan, w=1.0)
    publisher.put(goal_pose(1.0, 1.0, orientation=nan), reliable=True)
    publisher.put_cdr(b"\x00\x01\x00\x00\x07", reliable=True)
    await eventually(
        lambda: one_robot.refused == {"frame": 1, "out_of_range": 2, "bad_cdr": 1},
        what="four refused",
    )
    assert len(await _goals(db_url)) == 2
    rviz.close()


async def test_each_robot_takes_goals_on_its_own_namespace(
    two_robots: RvizLink, ros_session: zenoh.Session, db_url: str
) -> None:
    rviz = Ros2Node(ros_session, 0, "rviz2")
    r2 = rviz.publisher("/r2/goal_pose", ros2types.POSE_STAMPED)
    bare = rviz.publisher("/goal_pose", ros2types.POSE_STAMPED)
    await asyncio.sleep(SETTLE_S)
    r2.put(goal_pose(-1.0, 2.0), reliable=True)
    bare.put(goal_pose(0.5, 0.5), reliable=True)  # two robots, both namespaced: whose?
    await eventually(
        lambda: two_robots.goals_set == 1 and two_robots.refused["no_robot"] == 1,
        what="r2's goal and the bare one refused",
    )
    assert [tuple(r) for r in await _goals(db_url)] == [("r2", -1.0, 2.0, 0.15, "active")]
    rviz.close()


async def test_a_planned_path_goes_out_as_a_nav_path_on_plan(
    two_robots: RvizLink, ros_session: zenoh.Session, db_url: str
) -> None:
    paths: list[Any] = []
    viewer = Ros2Node(ros_session, 0, "rviz2")
    viewer.subscription(
        "/r1/plan",
        ros2types.PATH,
        lambda key, payload, att: paths.append(ros2types.decode(ros2types.PATH, payload)),
    )
    await asyncio.sleep(SETTLE_S)
    # as the planner writes a path, and notifies it with its image (or without one)
    planner = await as_service_role(db_url, "planner")
    conn = await asyncpg.connect(planner)
    notifier = bus.Notifier(two_robots.runtime.zenoh)
    try:
        row = await conn.fetchrow(
            "INSERT INTO planned_path (robot_id, stamp, target, target_x, target_y, xs, ys, "
            "length_m) VALUES ('r1', 7.5, 'goal', 1.0, 1.0, $1, $2, 2.0) "
            "RETURNING id, robot_id, stamp, xs, ys",
            [0.0, 1.0, 1.0],
            [0.0, 0.0, 1.0],
        )
        notifier.notify("planned_path", "r1", row["id"], dict(row))
        await eventually(lambda: len(paths) == 1, what="a Path")
        empty = await conn.fetchval(
            "INSERT INTO planned_path (robot_id, stamp, target, xs, ys, length_m) "
            "VALUES ('r1', 8.0, 'none', '{}', '{}', 0) RETURNING id"
        )
        notifier.notify("planned_path", "r1", empty)  # no image: read back
        await eventually(lambda: len(paths) == 2, what="an empty Path")
    finally:
        notifier.close()
        await conn.close()
    path = paths[0]
    assert path.header.frame_id == "map" and ros2types.seconds_of(path.header.stamp) == 7.5
    points = [(p.pose.position.x, p.pose.position.y) for p in path.poses]
    assert points == [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0)]
    yaws = [ros2types.yaw_of(p.pose.orientation) for p in path.poses]
    assert yaws == pytest.approx([0.0, math.pi / 2, math.pi / 2])  # towards the next
    assert paths[1].poses == [] and ros2types.seconds_of(paths[1].header.stamp) == 8.0
    viewer.close()

"""Migration 13: goal headings and routes (goal_waypoint), refused at the door and written
only by their documented writers.

Plain SQL through asyncpg, as a foreign client would, so what it shows holds for any client;
then the people's helper (common.contract.people.set_goal) writes a route in one transaction.
"""

from __future__ import annotations

import math
from collections.abc import AsyncIterator
from typing import Any

import asyncpg
import pytest

from common.contract import limits
from common.contract.people import Pose, check_route
from common.contract.roles import bootstrap, role_url
from common.errors import ContractError

NAN, INF, PI = math.nan, math.inf, math.pi

GOAL_SQL = "INSERT INTO goal (robot_id, x, y, yaw, yaw_tolerance_rad) VALUES ('r1', 1, 2, $1, $2)"
WAYPOINT_SQL = (
    "INSERT INTO goal_waypoint (goal_id, seq, x, y, tolerance_m, yaw, yaw_tolerance_rad) "
    "VALUES ($1, $2, $3, $4, $5, $6, $7)"
)


@pytest.fixture
async def client(db_url: str) -> AsyncIterator[asyncpg.Connection]:
    conn = await asyncpg.connect(db_url)
    await conn.execute("INSERT INTO robot (robot_id) VALUES ('r1')")
    try:
        yield conn
    finally:
        await conn.close()


async def refused(conn: asyncpg.Connection, sql: str, *args: Any) -> str:
    with pytest.raises(asyncpg.CheckViolationError) as caught:
        await conn.execute(sql, *args)
    assert caught.value.constraint_name
    return str(caught.value.constraint_name)


@pytest.mark.parametrize(
    ("yaw", "tolerance", "constraint"),
    [
        (NAN, None, "goal_yaw_bounded"),
        (INF, None, "goal_yaw_bounded"),
        (-INF, 0.1, "goal_yaw_bounded"),
        (math.nextafter(PI, INF), None, "goal_yaw_bounded"),
        (-3.2, None, "goal_yaw_bounded"),
        (0.0, NAN, "goal_yaw_tolerance_bounded"),
        (0.0, 0.0, "goal_yaw_tolerance_bounded"),
        (0.0, -0.1, "goal_yaw_tolerance_bounded"),
        (0.0, math.nextafter(PI, INF), "goal_yaw_tolerance_bounded"),
        (None, 0.1, "goal_yaw_tolerance_needs_yaw"),
    ],
)
async def test_a_goal_with_a_bad_heading_is_refused_naming_it(
    client: asyncpg.Connection, yaw: float | None, tolerance: float | None, constraint: str
) -> None:
    assert await refused(client, GOAL_SQL, yaw, tolerance) == constraint
    assert await client.fetchval("SELECT count(*) FROM goal") == 0
    # the tools' check refuses the same, naming the field
    with pytest.raises(ContractError, match="yaw"):
        limits.check_heading("goal", yaw, tolerance)


async def test_headings_at_the_bounds_and_goals_without_one_pass(
    client: asyncpg.Connection,
) -> None:
    for yaw, tolerance in [(PI, PI), (-PI, None), (0.0, 1e-9), (None, None)]:
        await client.execute("UPDATE goal SET status = 'superseded' WHERE status = 'active'")
        await client.execute(GOAL_SQL, yaw, tolerance)
        limits.check_heading("goal", yaw, tolerance)
    assert await client.fetchval("SELECT count(*) FROM goal") == 4


@pytest.mark.parametrize(
    ("seq", "x", "tolerance", "yaw", "yaw_tol", "constraint"),
    [
        (0, 1.0, 0.3, None, None, "goal_waypoint_seq_bounded"),
        (1001, 1.0, 0.3, None, None, "goal_waypoint_seq_bounded"),
        (1, NAN, 0.3, None, None, "goal_waypoint_xy_bounded"),
        (1, 1e6, 0.3, None, None, "goal_waypoint_xy_bounded"),
        (1, 1.0, 0.0, None, None, "goal_waypoint_tolerance_bounded"),
        (1, 1.0, NAN, None, None, "goal_waypoint_tolerance_bounded"),
        (1, 1.0, 0.3, NAN, None, "goal_waypoint_yaw_bounded"),
        (1, 1.0, 0.3, 4.0, None, "goal_waypoint_yaw_bounded"),
        (1, 1.0, 0.3, 1.0, 0.0, "goal_waypoint_yaw_tolerance_bounded"),
        (1, 1.0, 0.3, None, 0.2, "goal_waypoint_yaw_tolerance_needs_yaw"),
    ],
)
async def test_a_bad_waypoint_is_refused_naming_it(
    client: asyncpg.Connection,
    seq: int,
    x: float,
    tolerance: float,
    yaw: float | None,
    yaw_tol: float | None,
    constraint: str,
) -> None:
    goal = await client.fetchval(
        "INSERT INTO goal (robot_id, x, y) VALUES ('r1', 0, 0) RETURNING id"
    )
    args = (goal, seq, x, 0.0, tolerance, yaw, yaw_tol)
    assert await refused(client, WAYPOINT_SQL, *args) == constraint


async def test_a_route_of_ten_thousand_poses_is_refused_by_the_table_and_the_tools(
    client: asyncpg.Connection,
) -> None:
    goal = await client.fetchval(
        "INSERT INTO goal (robot_id, x, y) VALUES ('r1', 0, 0) RETURNING id"
    )
    n = 10_000
    sql = (
        "INSERT INTO goal_waypoint (goal_id, seq, x, y) "
        "SELECT $1, s, s * 0.01, 0 FROM generate_series(1, $2) AS s"
    )
    assert await refused(client, sql, goal, n) == "goal_waypoint_seq_bounded"
    assert await client.fetchval("SELECT count(*) FROM goal_waypoint") == 0
    await client.execute(sql, goal, limits.MAX_WAYPOINTS)  # the cap itself holds
    assert await client.fetchval("SELECT count(*) FROM goal_waypoint") == limits.MAX_WAYPOINTS
    # seq is unique per goal: the cap cannot be dodged by repeating numbers
    with pytest.raises(asyncpg.UniqueViolationError):
        await client.execute(WAYPOINT_SQL, goal, 5, 0.0, 0.0, 0.3, None, None)
    with pytest.raises(ContractError, match="waypoints: at most 1000 per goal, got 10000"):
        check_route(Pose(0, 0), [Pose(i * 0.01, 0) for i in range(n)])
    with pytest.raises(ContractError, match="waypoint 2 yaw"):
        check_route(Pose(0, 0), [Pose(1, 0), Pose(2, 0, yaw=NAN)])
    with pytest.raises(ContractError, match="waypoint 1 x"):
        check_route(Pose(0, 0), [Pose(INF, 0)])


@pytest.fixture
async def admin(empty_db_url: str) -> AsyncIterator[asyncpg.Connection]:
    conn = await asyncpg.connect(empty_db_url)
    try:
        await bootstrap(conn)
        await conn.execute("INSERT INTO robot (robot_id) VALUES ('r1')")
        yield conn
    finally:
        await conn.close()


async def test_people_write_routes_the_planner_writes_progress_and_nobody_else_does(
    admin: asyncpg.Connection, empty_db_url: str
) -> None:
    def connect(role: str) -> Any:
        return asyncpg.connect(role_url(empty_db_url, f"pnav_{role}", None))

    user, planner, controller = (
        await connect("user"),
        await connect("planner"),
        await connect("controller"),
    )
    try:
        goal = await user.fetchval(
            "INSERT INTO goal (robot_id, x, y, yaw, yaw_tolerance_rad) "
            "VALUES ('r1', 3, 0, 1.57, 0.05) RETURNING id"
        )
        await user.execute(WAYPOINT_SQL, goal, 1, 1.0, 0.0, 0.3, None, None)
        await user.execute(WAYPOINT_SQL, goal, 2, 2.0, 1.0, 0.3, 0.0, None)
        # the planner writes progress, never the route
        await planner.execute(
            "UPDATE goal_waypoint SET status = 'reached', reached_stamp = 4.5 "
            "WHERE goal_id = $1 AND seq = 1",
            goal,
        )
        with pytest.raises(asyncpg.InsufficientPrivilegeError):
            await planner.execute("UPDATE goal_waypoint SET x = 9 WHERE goal_id = $1", goal)
        with pytest.raises(asyncpg.InsufficientPrivilegeError):
            await planner.execute(WAYPOINT_SQL, goal, 3, 0.0, 0.0, 0.3, None, None)
        with pytest.raises(asyncpg.InsufficientPrivilegeError):
            await planner.execute("UPDATE goal SET yaw = 0 WHERE id = $1", goal)
        # people do not write the planner's progress, nor edit a route once written
        with pytest.raises(asyncpg.InsufficientPrivilegeError):
            await user.execute(
                "UPDATE goal_waypoint SET status = 'reached' WHERE goal_id = $1", goal
            )
        # a controller writes neither goals nor routes
        for sql in (
            "UPDATE goal SET status = 'reached' WHERE id = $1",
            "UPDATE goal_waypoint SET status = 'failed' WHERE goal_id = $1",
            "DELETE FROM goal_waypoint WHERE goal_id = $1",
        ):
            with pytest.raises(asyncpg.InsufficientPrivilegeError):
                await controller.execute(sql, goal)
        with pytest.raises(asyncpg.InsufficientPrivilegeError):
            await controller.execute(WAYPOINT_SQL, goal, 3, 0.0, 0.0, 0.3, None, None)
        rows = await admin.fetch(
            "SELECT seq, status, reached_stamp, yaw_tolerance_rad FROM goal_waypoint ORDER BY seq"
        )
        assert [tuple(r) for r in rows] == [(1, "reached", 4.5, None), (2, "pending", None, None)]
        # the route goes with its goal
        await admin.execute("DELETE FROM goal WHERE id = $1", goal)
        assert await admin.fetchval("SELECT count(*) FROM goal_waypoint") == 0
    finally:
        for conn in (user, planner, controller):
            await conn.close()

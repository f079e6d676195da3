"""Goal poses and routes against Postgres and Zenoh: a route written by people's helper in
one transaction is driven through with each waypoint's progress on its row, the goal's
heading is turned to before it is reached, and a waypoint row a foreign client adds after
the goal's notification, with none of its own, still reaches the planner (its period read
counts the goal's waypoints)."""

from __future__ import annotations

import math

from common.contract import people
from pnav._testing import eventually
from services.planner.service import PlannerService
from tests.contract.planner.conftest import ROBOT, World


async def statuses(world: World, goal: int) -> list[tuple[int, str, bool]]:
    rows = await world.db.pool.fetch(
        "SELECT seq, status, reached_stamp IS NOT NULL AS stamped FROM goal_waypoint "
        "WHERE goal_id = $1 ORDER BY seq",
        goal,
    )
    return [(r["seq"], r["status"], r["stamped"]) for r in rows]


async def test_a_route_is_driven_through_and_its_goal_heading_turned_to(
    world: World, planner: PlannerService
) -> None:
    await world.strategy("GOTO_AVOID")
    route = [people.Pose(1.0, 0.0), people.Pose(2.0, 0.0, stop=True)]
    goal = await people.set_goal(world.db, ROBOT, 2.0, 1.0, None, yaw=math.pi, waypoints=route)
    assert await statuses(world, goal) == [(1, "pending", False), (2, "pending", False)]
    assert (
        await world.db.pool.fetchval("SELECT yaw_tolerance_rad FROM goal WHERE id = $1", goal)
        == 0.1
    )  # the default with a yaw

    async def rows_are(want: list[tuple[int, str, bool]]) -> bool:
        return await statuses(world, goal) == want

    world.pose = (0.9, 0.0, 0.0)  # within waypoint 1's 0.3 m: passed
    await eventually(
        lambda: rows_are([(1, "reached", True), (2, "pending", False)]), 10.0, what="waypoint 1"
    )
    world.pose = (1.95, 0.0, 0.0)  # at waypoint 2, standing (the odometry's rates are 0)
    await eventually(
        lambda: rows_are([(1, "reached", True), (2, "reached", True)]), 10.0, what="waypoint 2"
    )
    world.pose = (2.0, 0.95, 0.0)  # at the goal's position, facing +x: turn to pi
    turn = await world.next_recommendation(
        lambda r: "turning to its heading" in r["reason"], what="the final turn"
    )
    assert turn["linear_mps"] == 0.0 and turn["angular_rps"] > 0
    assert await world.db.pool.fetchval("SELECT status FROM goal WHERE id = $1", goal) == "active"
    world.pose = (2.0, 0.95, math.pi - 0.05)
    reached = await world.next_recommendation(
        lambda r: "reached" in r["reason"] and r["inputs"].get("goal") == goal, what="reached"
    )
    assert (reached["linear_mps"], reached["angular_rps"]) == (0.0, 0.0)
    assert await world.db.pool.fetchval("SELECT status FROM goal WHERE id = $1", goal) == (
        "reached"
    )


async def test_a_waypoint_added_after_the_goal_without_a_notification_is_read_in_time(
    world: World, planner: PlannerService
) -> None:
    await world.strategy("GOTO_AVOID")
    goal = await world.goal(3.0, 0.0)
    await world.next_recommendation(lambda r: r["inputs"].get("goal") == goal, what="driving")
    # a foreign client's row, with no notification: the planner's period read finds it
    await world.db.pool.execute(
        "INSERT INTO goal_waypoint (goal_id, seq, x, y) VALUES ($1, 1, 0.0, 2.0)", goal
    )
    toward = await world.next_recommendation(
        lambda r: r["inputs"].get("waypoint") == 1, what="a recommendation toward the waypoint"
    )
    assert f"waypoint 1 of goal {goal}" in toward["reason"]
    path = await world.db.pool.fetchrow(
        "SELECT target_x, target_y FROM planned_path WHERE robot_id = $1 ORDER BY id DESC LIMIT 1",
        ROBOT,
    )
    assert (path["target_x"], path["target_y"]) == (0.0, 2.0)

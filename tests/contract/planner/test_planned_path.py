"""The planner's planned_path rows against Postgres and Zenoh (CONTRACT.md, planned_path):
one per plan, an empty one when the target is reached or gone, each notified with its
image; and GOTO_FAST's planner, which plans and stops but does not drive."""

from __future__ import annotations

import asyncio
from typing import Any

import asyncpg

from common import bus
from common.contract import keys
from pnav._testing import eventually
from services.planner.service import PlannerService
from tests.contract.planner.conftest import ROBOT, World


async def paths(world: World) -> list[asyncpg.Record]:
    return list(
        await world.db.pool.fetch(
            "SELECT * FROM planned_path WHERE robot_id = $1 ORDER BY id", ROBOT
        )
    )


async def test_a_goal_is_published_as_a_path_then_an_empty_one_once_it_is_reached(
    world: World, planner: PlannerService
) -> None:
    images: list[dict[str, Any]] = []

    def heard(sample: Any) -> None:
        note = bus.Notification.decode(str(sample.key_expr), bytes(sample.payload.to_bytes()))
        if note.row is not None:
            images.append(dict(note.row))

    listener = world.session.declare_subscriber(keys.notify_watch(keys.PLANNED_PATH), heard)
    try:
        await world.strategy("GOTO_AVOID")
        goal = await world.goal(2.0, 0.0)
        rows = await eventually(lambda: _nonempty(world), 10.0, what="a planned path")
        row = rows[0]
        assert row["goal_id"] == goal and row["target"] == "goal"
        assert (row["target_x"], row["target_y"]) == (2.0, 0.0)
        # no map: the straight line from where the robot stands to the goal
        assert list(row["xs"]) == [0.0, 2.0] and list(row["ys"]) == [0.0, 0.0]
        assert row["length_m"] == 2.0
        await eventually(lambda: _heard(images, row["id"]), 5.0, what="the path's image")
        image = next(i for i in images if i["id"] == row["id"])
        assert image["xs"] == [0.0, 2.0] and image["goal_id"] == goal

        world.pose = (1.95, 0.0, 0.0)  # within the goal's 0.15 m: reached
        empty = await eventually(lambda: _empty(world), 10.0, what="an empty path")
        assert empty["goal_id"] == goal and empty["target"] == "goal"
        assert list(empty["xs"]) == [] and empty["length_m"] == 0.0
        status = await world.db.pool.fetchval("SELECT status FROM goal WHERE id = $1", goal)
        assert status == "reached"
        await asyncio.sleep(0.5)
        assert len(await paths(world)) == 2  # one plan, one end: nothing while it waits
    finally:
        listener.undeclare()


async def test_goto_fast_plans_and_publishes_but_leaves_the_driving_to_the_local_controller(
    world: World, planner: PlannerService
) -> None:
    await world.strategy("GOTO_FAST")
    goal = await world.goal(0.0, 2.0)  # to the left: turn_then_move would turn in place
    await eventually(lambda: _nonempty(world), 10.0, what="a planned path")
    await asyncio.sleep(1.0)
    moves = [r for r in await world.recommendations() if r["inputs"].get("goal") == goal]
    assert moves == []  # "planner_drives": false

    world.pose = (0.0, 1.9, 1.57)
    stop = await world.next_recommendation(lambda r: r["inputs"].get("goal") == goal)
    assert (stop["linear_mps"], stop["angular_rps"]) == (0.0, 0.0)
    assert "reached" in stop["reason"]


async def test_a_cancelled_goal_leaves_an_empty_path_with_no_target(
    world: World, planner: PlannerService
) -> None:
    await world.strategy("GOTO_AVOID")
    goal = await world.goal(2.0, 0.0)
    await eventually(lambda: _nonempty(world), 10.0, what="a planned path")
    await world.execute(
        keys.GOAL, ROBOT, "UPDATE goal SET status = 'cancelled' WHERE id = $1", goal
    )
    empty = await eventually(lambda: _empty(world), 10.0, what="an empty path")
    assert empty["target"] == "none" and empty["goal_id"] is None
    assert empty["target_x"] is None and list(empty["xs"]) == []


async def _nonempty(world: World) -> list[asyncpg.Record]:
    return [r for r in await paths(world) if r["xs"]]


async def _empty(world: World) -> asyncpg.Record | None:
    return next((r for r in await paths(world) if not r["xs"]), None)


async def _heard(images: list[dict[str, Any]], row_id: int) -> bool:
    return any(i.get("id") == row_id for i in images)

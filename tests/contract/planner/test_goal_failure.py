"""The planner against Postgres and Zenoh: a goal the map rules out is marked failed, with its
reason, within 2 s of sim time, and `pnav status` shows it."""

from __future__ import annotations

import numpy as np

from common.contract import keys
from pnav._testing import eventually
from pnav.cli import stack_commands
from services.planner.service import PlannerService
from tests.contract.planner.conftest import ROBOT, World


async def walled_room(world: World) -> None:
    """3 x 2 m at 5 cm from (0, 0), walls all round, a rack at x 1.5-2.0, y 0.5-1.0."""
    grid = np.zeros((40, 60), dtype=np.uint8)
    grid[0, :] = grid[-1, :] = grid[:, 0] = grid[:, -1] = 100
    grid[10:20, 30:40] = 100
    async with world.db.transaction() as tx:
        await tx.conn.execute(
            "INSERT INTO map (map_id, resolution_m, origin_x, origin_y, width, height, grid) "
            "VALUES ('room', 0.05, 0, 0, 60, 40, $1)",
            grid.tobytes(),
        )
        await tx.conn.execute("UPDATE robot SET world = 'room' WHERE robot_id = $1", ROBOT)
        tx.changed(keys.MAP, None)
        tx.changed(keys.ROBOT, ROBOT)


async def test_a_goal_outside_the_map_fails_within_two_sim_seconds_and_status_shows_why(
    world: World, planner: PlannerService
) -> None:
    await walled_room(world)
    world.pose = (0.5, 0.5, 0.0)
    await world.strategy("GOTO_AVOID")
    reachable = await world.goal(2.5, 1.5)  # the map loaded and followed first
    await world.next_recommendation(lambda r: r["inputs"].get("goal") == reachable)

    set_at = world.now()
    goal_id = await world.goal(9.0, 1.0)
    row = await eventually(
        lambda: world.db.pool.fetchrow(
            "SELECT status, reason, finished_stamp FROM goal WHERE id = $1 AND status <> 'active'",
            goal_id,
        ),
        what="the goal marked failed",
    )
    reason = (
        "goal (9.00, 1.00) is outside the map (the map spans x 0.00 to 3.00 m, y 0.00 to 2.00 m)"
    )
    assert row["status"] == "failed" and row["reason"] == reason
    # sim time (the planner hears the clock every 0.05 s, so it may be a tick behind)
    assert set_at - 0.1 <= row["finished_stamp"] <= set_at + 2.0
    stop = await world.next_recommendation(lambda r: r["inputs"].get("goal") == goal_id)
    assert stop["linear_mps"] == 0.0 and stop["angular_rps"] == 0.0
    assert stop["reason"] == f"goal {goal_id} failed: {reason}: stop"

    rows = await world.db.pool.fetch(stack_commands.STATUS_SQL)
    text = "\n".join(stack_commands.status_lines(rows, width=300))
    assert f"goal {goal_id} failed: {reason}" in text, text
    assert " failed " in text.splitlines()[1], text  # in the goal column

    # inside the rack: failed too; a new reachable goal is followed as before
    inside = await world.goal(1.75, 0.75)
    row = await eventually(
        lambda: world.db.pool.fetchrow(
            "SELECT reason FROM goal WHERE id = $1 AND status = 'failed'", inside
        ),
        what="the goal in the rack marked failed",
    )
    assert row["reason"] == "goal (1.75, 0.75) is inside an obstacle on the map"
    again = await world.goal(2.5, 1.5)
    rec = await world.next_recommendation(lambda r: r["inputs"].get("goal") == again)
    assert "failed" not in rec["reason"]
    assert await world.db.pool.fetchval("SELECT status FROM goal WHERE id = $1", again) == "active"
    rows = await world.db.pool.fetch(stack_commands.STATUS_SQL)
    assert "failed" not in "\n".join(stack_commands.status_lines(rows, width=300))

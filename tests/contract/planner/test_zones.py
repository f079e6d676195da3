"""The planner against Postgres and Zenoh: a keepout zone people add while a robot follows a
route through it makes the planner publish a new route round it, with no restart; a goal
inside one fails naming the zone."""

from __future__ import annotations

import itertools

import asyncpg
import numpy as np

from common.contract import zones
from common.contract.zones import Zone
from pnav._testing import eventually
from services.planner.service import PlannerService
from tests.contract.planner.conftest import ROBOT, World
from tests.contract.planner.test_goal_failure import walled_room

# across the straight way from (0.3, 1.5) to (2.7, 1.5), in the room's upper corridor
SPILL = Zone("spill", zones.KEEPOUT, (1.0, 1.3, 1.3, 1.0), (1.1, 1.1, 1.9, 1.9))


def crosses(row: asyncpg.Record, zone: Zone) -> bool:
    """Whether the planned path's segments, sampled every 1 cm, enter ``zone``."""
    points = list(zip(row["xs"], row["ys"], strict=True))
    for (ax, ay), (bx, by) in itertools.pairwise(points):
        steps = max(1, int(np.hypot(bx - ax, by - ay) / 0.01))
        for t in np.linspace(0.0, 1.0, steps + 1):
            if zone.contains(ax + (bx - ax) * t, ay + (by - ay) * t):
                return True
    return False


async def newest_path(world: World, after: int = 0) -> asyncpg.Record | None:
    row: asyncpg.Record | None = await world.db.pool.fetchrow(
        "SELECT * FROM planned_path WHERE robot_id = $1 AND id > $2 AND cardinality(xs) > 0 "
        "ORDER BY id DESC LIMIT 1",
        ROBOT,
        after,
    )
    return row


async def test_a_keepout_zone_added_across_the_route_is_planned_round_at_once(
    world: World, planner: PlannerService
) -> None:
    await walled_room(world)
    world.pose = (0.3, 1.5, 0.0)
    await world.strategy("GOTO_AVOID")
    goal = await world.goal(2.7, 1.5)
    first = await eventually(lambda: newest_path(world), what="the first route")
    assert first["goal_id"] == goal and crosses(first, SPILL)  # straight through, no zone yet

    await zones.add_zone(world.db, SPILL)  # as `pnav zone add` writes it, notified
    second = await eventually(lambda: newest_path(world, first["id"]), what="a new route")
    assert second["goal_id"] == goal and not crosses(second, SPILL)
    assert second["length_m"] > first["length_m"]
    status = await world.db.pool.fetchval("SELECT status FROM goal WHERE id = $1", goal)
    assert status == "active"

    # removed: the straight way again
    assert await zones.remove_zone(world.db, "spill")
    third = await eventually(lambda: newest_path(world, second["id"]), what="the straight way")
    assert crosses(third, SPILL)


async def test_a_goal_inside_a_keepout_zone_fails_naming_it(
    world: World, planner: PlannerService
) -> None:
    await walled_room(world)
    world.pose = (0.3, 1.5, 0.0)
    await world.strategy("GOTO_AVOID")
    await zones.add_zone(world.db, SPILL)
    goal = await world.goal(1.15, 1.5)
    row = await eventually(
        lambda: world.db.pool.fetchrow(
            "SELECT status, reason FROM goal WHERE id = $1 AND status <> 'active'", goal
        ),
        what="the goal marked failed",
    )
    assert row["status"] == "failed"
    assert row["reason"] == "goal (1.15, 1.50) is inside keepout zone 'spill'"

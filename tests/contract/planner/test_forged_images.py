"""Forged odometry and battery images (CONTRACT.md "Row images", "Forged images"): the
planner holds each image to its table's rules before it stands in for a read, so an image no
row could be (a NaN heading, another robot's row on r1's key, an id no sequence gives, a
battery at 150 %) is dropped, counted, and the table read instead: a forged pose at the goal
does not mark it reached.
"""

from __future__ import annotations

import math
from typing import Any

from common.contract import keys
from pnav._testing import eventually
from services.planner.service import PlannerService
from services.planner.store import PlannerStore
from tests.contract.planner.conftest import ROBOT, World

FORGED_ID = 10**9


def at_goal(world: World, row_id: int, **changes: Any) -> dict[str, Any]:
    image = {"id": row_id, "robot_id": ROBOT, "stamp": world.now(), "seq": 0, "x": 2.0}
    image |= {"y": 0.0, "yaw": 0.0, "linear_mps": 0.0, "angular_rps": 0.0}
    return {**image, **changes}


async def test_forged_odometry_and_battery_images_are_dropped_and_counted(
    world: World, planner: PlannerService
) -> None:
    store = planner.store
    assert isinstance(store, PlannerStore)
    await world.strategy("GOTO_AVOID")
    goal = await world.goal(2.0, 0.0)
    first = await world.next_recommendation(lambda r: r["inputs"].get("goal") == goal)
    forgeries = [
        at_goal(world, FORGED_ID, yaw=math.nan),
        at_goal(world, FORGED_ID + 1, robot_id="r2"),
        at_goal(world, 0),
    ]
    for image in forgeries:
        world.db.notifier.notify(keys.ODOMETRY, ROBOT, image["id"], image)
    battery = {"id": FORGED_ID, "robot_id": ROBOT, "stamp": world.now(), "energy_wh": 29.97}
    battery |= {"capacity_wh": 19.98, "percentage": 150.0, "charging": False, "power_w": 0.0}
    world.db.notifier.notify(keys.BATTERY, ROBOT, FORGED_ID, battery)
    expected = {keys.ODOMETRY: len(forgeries), keys.BATTERY: 1}
    await eventually(
        lambda: store.images_refused == expected, within=30, what="every forgery refused"
    )
    assert planner.images_refused() == expected
    later = await world.next_recommendation(
        lambda r: r["inputs"].get("goal") == goal, after=first["id"] + 3
    )
    assert later["inputs"]["odometry"] < FORGED_ID  # a row the bridge wrote
    status = await world.db.pool.fetchval("SELECT status FROM goal WHERE id = $1", goal)
    assert status == "active"  # the forged pose at the goal reached nothing

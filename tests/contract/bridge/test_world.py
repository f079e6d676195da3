"""The sim's world -> robot, map and charging_station rows, each followed by a notification."""

from __future__ import annotations

import asyncio

import asyncpg
import pytest

from common.contract import keys
from pnav._testing import eventually
from tests.contract.bridge.conftest import (
    BridgeFactory,
    FakeSim,
    bridge_with_world,
    count,
)
from tests.unit.bridge import payloads

pytestmark = pytest.mark.timeout(60)


async def test_the_world_from_the_queryable_becomes_rows_and_notifications(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    notes = sim.listen(keys.NOTIFY_ALL)
    world = payloads.world(robots=("r1", "r2"), max_linear_mps=0.5, max_angular_rps=1.5)
    await bridge_with_world(start_bridge, sim, world)

    robots = await conn.fetch("SELECT * FROM robot ORDER BY robot_id")
    assert [r["robot_id"] for r in robots] == ["r1", "r2"]
    r1 = robots[0]
    assert (r1["max_linear_mps"], r1["max_angular_rps"]) == (0.5, 1.5)
    assert (r1["wheel_radius_m"], r1["wheel_separation_m"]) == (0.033, 0.160)
    assert (r1["footprint_radius_m"], r1["battery_capacity_wh"]) == (0.105, 19.98)
    assert (r1["model"], r1["world"]) == ("turtlebot3_burger", "test_world")

    m = await conn.fetchrow("SELECT * FROM map")
    assert m["map_id"] == "test_world"
    assert (m["resolution_m"], m["origin_x"], m["origin_y"], m["origin_yaw"]) == (
        0.5,
        -1.0,
        -0.5,
        0.0,
    )
    assert (m["width"], m["height"], m["source"]) == (4, 3, "worlds/test.yaml")
    assert bytes(m["grid"]) == world["map"]["grid"]

    station = await conn.fetchrow("SELECT * FROM charging_station")
    assert dict(station) == {
        "station_id": "c1",
        "map_id": "test_world",
        "x": 2.0,
        "y": 3.0,
        "radius_m": 0.3,
        "charge_power_w": 10.0,
    }

    await eventually(lambda: len(notes.items) >= 4, what="four notifications")
    got = {key for key, _ in notes.items}
    assert got == {
        keys.notify_key(keys.ROBOT, "r1"),
        keys.notify_key(keys.ROBOT, "r2"),
        keys.notify_key(keys.MAP),
        keys.notify_key(keys.CHARGING_STATION),
    }
    body = dict(notes.items)[keys.notify_key(keys.MAP)]
    # a hint without an id, so without an image; numbered by its publisher (the bridge)
    assert body == {"table": "map", "robot": None, "id": None, "src": body["src"], "seq": 1}


async def test_a_republished_world_is_written_once_and_a_changed_one_again(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge = await start_bridge()  # no queryable: the world comes by publication
    world = payloads.world(stations=(("c1", 2.0, 3.0), ("c2", -1.0, 0.0)))
    sim.put(keys.SIM_WORLD, world)
    await eventually(lambda: bridge.counters.worlds_applied == 1, what="the world")
    first = await conn.fetchval("SELECT registered_at FROM robot WHERE robot_id = 'r1'")
    assert await count(conn, "charging_station") == 2

    for _ in range(3):  # the sim republishes every second
        sim.put(keys.SIM_WORLD, world)
    await eventually(lambda: bridge.counters.worlds_unchanged == 3, what="the repeats")
    await asyncio.sleep(0.1)
    assert bridge.counters.worlds_applied == 1
    assert await count(conn, "robot") == 1
    assert await conn.fetchval("SELECT registered_at FROM robot WHERE robot_id = 'r1'") == first

    # the sim loads another version of the world: a robot more, c2 gone, c1 moved
    changed = payloads.world(robots=("r1", "r9"), stations=(("c1", 4.0, 4.0),))
    sim.put(keys.SIM_WORLD, changed)
    await eventually(lambda: bridge.counters.worlds_applied == 2, what="the changed world")
    assert await conn.fetchval("SELECT array_agg(robot_id ORDER BY robot_id) FROM robot") == [
        "r1",
        "r9",
    ]
    assert [
        tuple(r) for r in await conn.fetch("SELECT station_id, x, y FROM charging_station")
    ] == [("c1", 4.0, 4.0)]
    assert "r9" in bridge.robots
    assert await count(conn, "map") == 1


async def test_a_malformed_world_is_counted_and_writes_nothing(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge = await start_bridge()
    broken = payloads.world()
    broken["map"]["grid"] = b"\x00"  # 1 byte for a 4 x 3 grid
    sim.put(keys.SIM_WORLD, broken)
    await eventually(lambda: bridge.counters.worlds_malformed == 1, what="a refusal")
    sim.put(keys.SIM_WORLD, broken)  # republished: refused again, without decoding
    sim.put(keys.SIM_WORLD, b"\xc1 not msgpack")
    await eventually(lambda: bridge.counters.worlds_malformed == 3, what="more refusals")
    assert await count(conn, "robot") == await count(conn, "map") == 0
    sim.put(keys.SIM_WORLD, payloads.world())
    await eventually(lambda: bridge.counters.worlds_applied == 1, what="the good world")


async def test_a_world_answered_late_by_the_queryable_is_still_fetched(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    """A sim that publishes once, before the bridge listens, is asked again until it answers."""
    bridge = await start_bridge()
    await asyncio.sleep(0.2)
    sim.serve_world(payloads.world(robots=("late",)))
    await eventually(lambda: bridge.counters.worlds_applied == 1, what="the world", within=5)
    assert await conn.fetchval("SELECT robot_id FROM robot") == "late"
    assert "late" in bridge.robots


async def test_the_bridge_knows_robots_already_in_the_table(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    await conn.execute("INSERT INTO robot (robot_id) VALUES ('old')")
    bridge = await start_bridge()
    assert bridge.robots == {"old": 360}  # its lidar: the table's default, the Burger's
    # a robot inserted later by someone else is picked up through its notification
    await conn.execute("INSERT INTO robot (robot_id) VALUES ('new')")
    sim.notifier.notify(keys.ROBOT, "new", None)
    await eventually(lambda: "new" in bridge.robots, what="the new robot")

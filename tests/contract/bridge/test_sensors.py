"""Sensor messages -> contract rows with the right values, each followed by a notification."""

from __future__ import annotations

import asyncio
import math

import asyncpg
import pytest

from common.contract import keys
from pnav._testing import eventually
from tests.contract.bridge.conftest import (
    SETTLE_S,
    BridgeFactory,
    FakeSim,
    bridge_with_world,
    count,
    subscribers_known,
)
from tests.unit.bridge import payloads

pytestmark = pytest.mark.timeout(60)


async def test_each_sensor_topic_becomes_its_row_and_notification(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge = await bridge_with_world(start_bridge, sim, payloads.world())
    notes = {
        table: sim.listen(keys.notify_watch(table))
        for table in (keys.ODOMETRY, keys.LASER_SCAN, keys.BATTERY, keys.COLLISION_EVENT)
    }
    await subscribers_known(bridge, [keys.notify_key(table, "r1") for table in notes])
    sent = {
        keys.ODOMETRY: (keys.ODOM, payloads.odom(seq=4, stamp=12.5)),
        keys.LASER_SCAN: (keys.SCAN, payloads.scan(seq=2, stamp=12.4)),
        keys.BATTERY: (keys.BATTERY_MSG, payloads.battery(seq=1, stamp=12.0)),
        keys.COLLISION_EVENT: (keys.COLLISION, payloads.collision(seq=0, stamp=12.6)),
    }
    for topic, body in sent.values():
        sim.sensor("r1", topic, body)

    ids = {}
    for table, inbox in notes.items():
        for _ in range(3):
            try:
                key, body = await inbox.next(within=3.0)
                break
            except AssertionError:
                # A written row must be followed by its notification; a reading that never
                # reached the bridge (a sensor stream may drop one, CONTRACT.md) is sent again.
                assert await count(conn, table) == 0, f"{table}: row written, never notified"
                sim.sensor("r1", *sent[table])
        else:
            raise AssertionError(f"{table}: no row and no notification after three sends")
        assert key == keys.notify_key(table, "r1")
        assert body["table"] == table and body["robot"] == "r1"
        ids[table] = body["id"]

    odom = await conn.fetchrow("SELECT * FROM odometry")
    assert odom["id"] == ids[keys.ODOMETRY]
    assert (odom["robot_id"], odom["stamp"], odom["seq"]) == ("r1", 12.5, 4)
    assert (odom["x"], odom["y"], odom["yaw"]) == (1.5, -2.25, 0.5)
    assert (odom["linear_mps"], odom["angular_rps"]) == (0.2, -0.1)
    assert odom["received_at"] is not None

    scan = await conn.fetchrow("SELECT * FROM laser_scan")
    assert scan["id"] == ids[keys.LASER_SCAN]
    assert (scan["stamp"], scan["seq"], scan["range_min"], scan["range_max"]) == (
        12.4,
        2,
        0.12,
        3.5,
    )
    assert scan["angle_min"] == 0.0
    assert scan["angle_increment"] == pytest.approx(math.tau / 360)
    expected = payloads.scan_ranges()
    assert len(scan["ranges"]) == 360
    assert scan["ranges"] == pytest.approx(expected, rel=1e-6)  # real[] is float32
    assert await conn.fetchval("SELECT ranges[360] = 'Infinity'::real FROM laser_scan")

    bat = await conn.fetchrow("SELECT * FROM battery")
    assert bat["id"] == ids[keys.BATTERY]
    assert (bat["stamp"], bat["energy_wh"], bat["capacity_wh"]) == (12.0, 15.0, 19.98)
    assert bat["percentage"] == pytest.approx(15.0 / 19.98 * 100)
    assert (bat["charging"], bat["power_w"]) == (True, -5.0)

    hit = await conn.fetchrow("SELECT * FROM collision_event")
    assert hit["id"] == ids[keys.COLLISION_EVENT]
    assert (hit["stamp"], hit["other"], hit["x"], hit["y"]) == (12.6, "wall_3", 0.75, 1.25)


async def test_a_burst_is_written_in_batches_with_the_newest_id_notified(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge = await bridge_with_world(start_bridge, sim, payloads.world(robots=("r1", "r2")))
    notes = sim.listen(keys.notify_watch(keys.ODOMETRY))
    await asyncio.sleep(SETTLE_S)
    n = 400
    for seq in range(n):
        for robot in ("r1", "r2"):
            sim.sensor(robot, keys.ODOM, payloads.odom(seq=seq, stamp=seq / 30))
    await eventually(
        lambda: bridge.counters.rows_written[keys.ODOMETRY] == 2 * n, what="every row", within=20
    )
    # rows came faster than one INSERT each: they were grouped
    assert bridge.counters.batches[keys.ODOMETRY] < 2 * n
    assert bridge.counters.largest_batch[keys.ODOMETRY] > 1
    for robot in ("r1", "r2"):
        seqs = await conn.fetchval(
            "SELECT array_agg(seq ORDER BY id) FROM odometry WHERE robot_id = $1", robot
        )
        assert seqs == list(range(n))  # none lost, none reordered
    newest = dict(await conn.fetch("SELECT robot_id, max(id) FROM odometry GROUP BY robot_id"))
    await eventually(
        lambda: {b["robot"]: b["id"] for _, b in notes.items} == newest,
        what="the newest id per robot",
    )
    assert await count(conn, "odometry") == 2 * n


async def test_rows_postgres_refuses_cost_only_themselves(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge = await bridge_with_world(start_bridge, sim, payloads.world(robots=("r1", "r2")))
    # r2 disappears behind the bridge's back: its rows now break the foreign key
    await conn.execute("DELETE FROM robot WHERE robot_id = 'r2'")
    n = 100
    for seq in range(n):
        for robot in ("r1", "r2"):
            sim.sensor(robot, keys.ODOM, payloads.odom(seq=seq))
    await eventually(
        lambda: bridge.counters.rejected_by_db[keys.ODOMETRY] == n, what="r2's refusals"
    )
    await eventually(lambda: bridge.counters.rows_written[keys.ODOMETRY] == n, what="r1's rows")
    assert await conn.fetchval("SELECT count(*) FROM odometry WHERE robot_id = 'r1'") == n


async def test_the_writer_survives_losing_its_connections(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge = await bridge_with_world(start_bridge, sim, payloads.world())
    sim.sensor("r1", keys.ODOM, payloads.odom(seq=0))
    await eventually(lambda: bridge.counters.rows_written[keys.ODOMETRY] == 1, what="a row")
    killed = await conn.fetchval(
        "SELECT count(pg_terminate_backend(pid)) FROM pg_stat_activity"
        " WHERE application_name = 'pnav-bridge-sensors'"
    )
    assert killed >= 1
    for seq in range(1, 30):  # the first write after the loss fails; later ones reconnect
        sim.sensor("r1", keys.ODOM, payloads.odom(seq=seq))
        await asyncio.sleep(0.02)
    await eventually(
        lambda: conn.fetchval("SELECT max(seq) = 29 FROM odometry"), what="rows after the loss"
    )

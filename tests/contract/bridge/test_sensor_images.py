"""The images the bridge's sensor notifications carry are the rows as committed (CONTRACT.md,
"Row images"), read back and compared column by column; with PNAV_NOTIFY_IMAGES=off the
bridge process sends none and the rows are all there for a reader of the table."""

from __future__ import annotations

import asyncio
import os
import signal
import sys
from collections.abc import Callable
from typing import Any

import asyncpg
import pytest

from common.config import ZenohSettings
from common.contract import keys
from pnav._testing import eventually
from tests.contract.bridge.conftest import (
    SETTLE_S,
    BridgeFactory,
    FakeSim,
    Inbox,
    bridge_with_world,
    count,
)
from tests.unit.bridge import payloads

pytestmark = pytest.mark.timeout(90)

SENSORS: dict[str, tuple[str, Callable[..., dict[str, Any]]]] = {
    keys.ODOMETRY: (keys.ODOM, payloads.odom),
    keys.LASER_SCAN: (keys.SCAN, payloads.scan),
    keys.BATTERY: (keys.BATTERY_MSG, payloads.battery),
    keys.COLLISION_EVENT: (keys.COLLISION, payloads.collision),
}


async def row_as_read(conn: asyncpg.Connection, table: str, row_id: int) -> dict[str, Any]:
    """Every column of row ``row_id`` but ``received_at`` (the database's, not written)."""
    row = await conn.fetchrow(f"SELECT * FROM {table} WHERE id = $1", row_id)
    assert row is not None, f"{table} {row_id}: notified, not in the table"
    return {k: v for k, v in row.items() if k != "received_at"}


async def notified(
    inbox: Inbox, conn: asyncpg.Connection, table: str, resend: Callable[[], None]
) -> dict[str, Any]:
    """The next notification on ``inbox``; a reading lost on its way to the bridge (a sensor
    stream may drop one) is sent again, a row written and never notified fails."""
    for _ in range(3):
        try:
            return (await inbox.next(within=3.0))[1]  # type: ignore[no-any-return]
        except AssertionError:
            assert await count(conn, table) == 0, f"{table}: row written, never notified"
            resend()
    raise AssertionError(f"{table}: no row and no notification after three sends")


async def test_each_sensor_notification_carries_its_row_as_committed(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    await bridge_with_world(start_bridge, sim, payloads.world())
    inboxes = {table: sim.listen(keys.notify_watch(table)) for table in SENSORS}
    await asyncio.sleep(SETTLE_S)
    for table, (topic, body) in SENSORS.items():
        sent = body(seq=7, stamp=12.5, **({"yaw": 4.0} if table == keys.ODOMETRY else {}))

        def resend(topic: str = topic, sent: dict[str, Any] = sent) -> None:
            sim.sensor("r1", topic, sent)

        resend()
        note = await notified(inboxes[table], conn, table, resend)
        assert note["row"] == await row_as_read(conn, table, note["id"])
        assert note["row"]["id"] == note["id"] and note["row"]["robot_id"] == "r1"
    # what the image holds is what was written, not what was sent: a scan's ranges as real[]
    # keeps them (float32), a yaw wrapped into (-pi, pi]
    scan = (await conn.fetchrow("SELECT ranges FROM laser_scan"))["ranges"]
    assert scan != payloads.scan_ranges() and scan == pytest.approx(payloads.scan_ranges())
    assert await conn.fetchval("SELECT yaw FROM odometry") == pytest.approx(4.0 - 6.283185307)


async def test_a_burst_for_two_robots_is_one_statement_and_each_image_is_its_row(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    robots = ("r1", "r2")
    bridge = await bridge_with_world(start_bridge, sim, payloads.world(robots=robots))
    inbox = sim.listen(keys.notify_watch(keys.LASER_SCAN))
    await asyncio.sleep(SETTLE_S)
    n = 60
    for seq in range(n):
        for robot in robots:
            sim.sensor(robot, keys.SCAN, payloads.scan(seq=seq, stamp=seq / 5, angle_min=seq / n))
    await eventually(
        lambda: bridge.counters.rows_written[keys.LASER_SCAN] == len(robots) * n,
        what="every scan",
        within=20,
    )
    newest = dict(await conn.fetch("SELECT robot_id, max(id) FROM laser_scan GROUP BY robot_id"))
    await eventually(
        lambda: {b["robot"]: b["id"] for _, b in inbox.items} == newest, what="the newest ids"
    )
    # rows of both robots went together (fewer statements than rows, one with both robots)
    assert bridge.counters.batches[keys.LASER_SCAN] < len(robots) * n
    assert bridge.counters.largest_batch[keys.LASER_SCAN] >= len(robots)
    for key, body in inbox.items:
        assert key == keys.notify_key(keys.LASER_SCAN, body["robot"])
        assert body["row"] == await row_as_read(conn, keys.LASER_SCAN, body["id"])


async def test_with_images_off_the_bridge_process_sends_hints_and_the_rows_are_all_there(
    db_url: str, zenoh_settings: ZenohSettings, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    sim.serve_world(payloads.world())
    inboxes = {table: sim.listen(keys.notify_watch(table)) for table in SENSORS}
    robot_notes = sim.listen(keys.notify_watch(keys.ROBOT))
    await asyncio.sleep(SETTLE_S)
    env = {
        **os.environ,
        "PNAV_DATABASE_URL": db_url,
        **zenoh_settings.to_env(),
        "PNAV_INSTANCE": "bridge-no-images",
        "PNAV_NOTIFY_IMAGES": "off",
    }
    child = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "services.bridge", env=env, stderr=asyncio.subprocess.DEVNULL
    )
    try:
        await robot_notes.next(within=20)  # the world is in
        await asyncio.sleep(SETTLE_S)  # its sensor subscriptions reach the router
        for table, (topic, body) in SENSORS.items():

            def resend(topic: str = topic, body: Callable[..., dict[str, Any]] = body) -> None:
                sim.sensor("r1", topic, body(seq=3, stamp=4.5))

            resend()
            note = await notified(inboxes[table], conn, table, resend)
            assert "row" not in note and note["src"] and note["seq"] == 1
            # a reader of the table finds the row the hint names, the newest of the robot
            row = await row_as_read(conn, table, note["id"])
            assert (row["robot_id"], row["stamp"]) == ("r1", 4.5)
            assert (
                await conn.fetchval(f"SELECT max(id) FROM {table} WHERE robot_id = 'r1'")
                == note["id"]
            )
    finally:
        child.send_signal(signal.SIGTERM)
        assert await asyncio.wait_for(child.wait(), 20) == 0

"""command2robot images -> cmd_vel without a query; the query when the image cannot be trusted.

The decision service's notifications are played by a plain Zenoh session: with the row's
image (as a writer with PNAV_NOTIFY_IMAGES on sends it), without, with a column missing, or
with a ``seq`` skipped. The bridge's periodic re-read is set to 30 s so that every query of
command2robot it makes (``Counters.command_reads``) is one a notification asked for.
"""

from __future__ import annotations

from typing import Any

import asyncpg
import pytest

from common.bus import Notification
from common.contract import keys
from common.footprint import Footprint
from pnav._testing import eventually
from services.bridge import Bridge, BridgeSettings
from tests.contract.bridge.conftest import BridgeFactory, FakeSim, Inbox, command, ready, vel

pytestmark = pytest.mark.timeout(60)

# no periodic re-read during a test: each query counted is one a notification caused
QUIET = BridgeSettings(command_period_s=30.0, prune_period_s=30.0, world_retry_s=0.5)
KEY = keys.notify_key(keys.COMMAND2ROBOT, "r1")


async def decided(
    conn: asyncpg.Connection, linear: float, angular: float, *, stamp: float = 10.0
) -> tuple[int, dict[str, Any]]:
    """Insert a decision for r1 as the decision service would; its id and its image (every
    column as written; created_at is the database's)."""
    row = await conn.fetchrow(
        "INSERT INTO command2robot (robot_id, stamp, linear_mps, angular_rps, source,"
        " considered_ids, reason) VALUES ('r1', $1, $2, $3, 'test', '{4,5}', 'a test')"
        " RETURNING id, robot_id, stamp, linear_mps, angular_rps, recommendation_id, source,"
        " considered_ids, reason",
        stamp,
        linear,
        angular,
    )
    return row["id"], dict(row)


def publish(sim: FakeSim, row_id: int, image: dict[str, Any] | None, seq: int) -> None:
    """A notification from publisher "dec" numbered ``seq`` (to make a gap at will)."""
    note = Notification(keys.COMMAND2ROBOT, "r1", row_id, image, "dec", seq)
    sim.put(KEY, note.encode())


async def started(start_bridge: BridgeFactory, sim: FakeSim) -> tuple[Bridge, Inbox]:
    bridge, cmd_vel = await ready(start_bridge, sim, settings=QUIET)
    # the world's robot notifications made the limits stale; wait for their re-read
    await eventually(lambda: bridge.commands.limits.of("r1") is not None, what="r1's limits")
    return bridge, cmd_vel


async def test_a_command_with_its_image_is_sent_without_a_query_clamped_and_once(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge, cmd_vel = await started(start_bridge, sim)
    reads = bridge.counters.command_reads
    row_id, image = await decided(conn, 1.0, -0.5, stamp=9.98)
    sim.notifier.notify(keys.COMMAND2ROBOT, "r1", row_id, image)
    key, body = await cmd_vel.next()
    assert (key, vel(body)) == (keys.robot_key("r1", keys.CMD_VEL), (0.22, -0.5, row_id))
    assert body["decided_stamp"] == 9.98
    assert bridge.counters.command_reads == reads  # no query
    assert bridge.counters.commands_from_images == 1

    sim.notifier.notify(keys.COMMAND2ROBOT, "r1", row_id, image)  # the same row again
    assert await cmd_vel.quiet(0.3) == []
    assert (bridge.counters.commands_out, bridge.counters.command_reads) == (1, reads)


async def test_without_an_image_or_with_a_column_missing_the_relay_reads_the_table(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge, cmd_vel = await started(start_bridge, sim)
    reads = bridge.counters.command_reads
    row_id = await command(conn, sim, 0.1, 0.2)  # a plain hint, as a foreign client sends
    assert vel((await cmd_vel.next())[1]) == (0.1, 0.2, row_id)
    assert bridge.counters.command_reads == reads + 1

    row_id, image = await decided(conn, 0.15, 0.0)
    del image["linear_mps"]
    sim.notifier.notify(keys.COMMAND2ROBOT, "r1", row_id, image)
    assert vel((await cmd_vel.next())[1]) == (0.15, 0.0, row_id)  # the table's value
    assert bridge.counters.command_reads == reads + 2
    assert bridge.counters.commands_from_images == 0


async def test_a_seq_gap_sends_the_relay_to_the_table(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge, cmd_vel = await started(start_bridge, sim)
    reads = bridge.counters.command_reads
    first, image = await decided(conn, 0.1, 0.0)
    publish(sim, first, image, seq=1)
    assert vel((await cmd_vel.next())[1]) == (0.1, 0.0, first)
    assert bridge.counters.command_reads == reads  # from the image

    await decided(conn, 0.05, 0.0)  # its notification (seq 2) never arrives
    third, image = await decided(conn, 0.2, 0.1)
    publish(sim, third, image, seq=3)
    assert vel((await cmd_vel.next())[1]) == (0.2, 0.1, third)
    assert bridge.counters.command_reads == reads + 1  # the gap: read the table
    assert bridge.counters.command_notes_lost == 1  # and counted

    fourth, image = await decided(conn, 0.0, 0.3)
    publish(sim, fourth, image, seq=4)  # numbered on from 3: trusted again
    assert vel((await cmd_vel.next())[1]) == (0.0, 0.3, fourth)
    assert bridge.counters.command_reads == reads + 1
    assert bridge.counters.commands_from_images == 2


async def test_limits_changed_by_a_robot_notification_are_read_before_the_next_image(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge, cmd_vel = await started(start_bridge, sim)
    await conn.execute("UPDATE robot SET max_linear_mps = 0.5 WHERE robot_id = 'r1'")
    sim.notifier.notify(keys.ROBOT, "r1", None)
    await eventually(
        lambda: bridge.commands.limits.of("r1") == (0.5, 2.84, Footprint.of(0.105), 2.5),
        what="new limits",
    )
    row_id, image = await decided(conn, 1.0, 0.0)
    sim.notifier.notify(keys.COMMAND2ROBOT, "r1", row_id, image)
    assert vel((await cmd_vel.next())[1]) == (0.5, 0.0, row_id)
    assert bridge.counters.commands_from_images == 1


async def test_limits_changed_without_a_notification_are_caught_by_the_periodic_read(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge, cmd_vel = await ready(start_bridge, sim)  # the usual 50 ms re-read
    row_id = await command(conn, sim, 0.1, 0.0)
    assert vel((await cmd_vel.next())[1]) == (0.1, 0.0, row_id)
    await conn.execute("UPDATE robot SET max_angular_rps = 1.0 WHERE robot_id = 'r1'")
    # the periodic read returns r1's limits with its command, sees them differ, re-reads
    await eventually(
        lambda: bridge.commands.limits.of("r1") == (0.22, 1.0, Footprint.of(0.105), 2.5),
        what="new limits",
    )
    row_id, image = await decided(conn, 0.0, -2.0)
    sim.notifier.notify(keys.COMMAND2ROBOT, "r1", row_id, image)
    assert vel((await cmd_vel.next())[1]) == (0.0, -1.0, row_id)


async def test_an_image_of_a_robot_the_relay_has_no_limits_for_is_read_from_the_table(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge, cmd_vel = await started(start_bridge, sim)
    # a robot added behind the bridge's back, with no robot notification
    await conn.execute("INSERT INTO robot (robot_id, max_linear_mps) VALUES ('r9', 0.3)")
    reads = bridge.counters.command_reads
    row = await conn.fetchrow(
        "INSERT INTO command2robot (robot_id, stamp, linear_mps, angular_rps)"
        " VALUES ('r9', 10.0, 1.0, 0.0) RETURNING id, robot_id, stamp, linear_mps, angular_rps"
    )
    sim.notifier.notify(keys.COMMAND2ROBOT, "r9", row["id"], dict(row))
    key, body = await cmd_vel.next()
    assert (key, vel(body)) == (keys.robot_key("r9", keys.CMD_VEL), (0.3, 0.0, row["id"]))
    assert bridge.counters.command_reads == reads + 1
    assert bridge.counters.commands_from_images == 0

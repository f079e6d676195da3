"""The bridge prunes the sensor tables, so a long run keeps them bounded."""

from __future__ import annotations

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


async def test_odometry_stays_bounded_after_many_messages(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    await conn.execute("UPDATE retention_policy SET keep_rows_per_robot = 20")
    bridge = await bridge_with_world(start_bridge, sim, payloads.world())  # prunes every 0.3 s
    counters = bridge.counters
    sizes = []
    for burst in range(5):
        for i in range(100):
            seq = burst * 100 + i
            sim.sensor("r1", keys.ODOM, payloads.odom(seq=seq, stamp=seq / 30))
        sent = (burst + 1) * 100

        def written(sent: int = sent) -> bool:
            return counters.rows_written[keys.ODOMETRY] == sent

        def pruned(sent: int = sent) -> bool:
            return counters.rows_pruned >= sent - 20

        await eventually(written, what="the burst's rows")
        await eventually(pruned, what="a prune")
        sizes.append(await count(conn, "odometry"))
    assert all(size <= 20 for size in sizes), sizes
    kept = await conn.fetchval("SELECT array_agg(seq ORDER BY seq) FROM odometry")
    assert kept == list(range(480, 500))  # the newest rows are the ones kept

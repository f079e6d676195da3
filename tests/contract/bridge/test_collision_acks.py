"""Collision events: one row per (robot, run, seq) however often the robot sends one, and an
acknowledgement per event once its row is committed (CONTRACT.md, "Robot and sim")."""

from __future__ import annotations

import asyncio

import asyncpg

from common.contract import keys
from pnav._testing import eventually
from tests.contract.bridge.conftest import SETTLE_S, BridgeFactory, FakeSim, bridge_with_world
from tests.unit.bridge import payloads


async def test_a_resent_collision_event_is_one_row_and_each_copy_is_acknowledged(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge = await bridge_with_world(start_bridge, sim, payloads.world())
    acks = sim.listen(keys.robot_watch(keys.COLLISION_ACK))
    await asyncio.sleep(SETTLE_S)
    event = payloads.collision(seq=4, stamp=7.5, run="run-a")
    for _ in range(3):  # the robot resending an event it has no acknowledgement for
        sim.sensor("r1", keys.COLLISION, event)
    for _ in range(3):
        key, body = await acks.next()
        assert key == keys.robot_key("r1", keys.COLLISION_ACK)
        assert body == {"run": "run-a", "seq": 4}
    rows = await conn.fetch("SELECT stamp, other, seq, run FROM collision_event")
    assert [tuple(r) for r in rows] == [(7.5, "wall_3", 4, "run-a")]
    assert bridge.counters.collision_acks == 3


async def test_the_same_seq_in_another_run_is_another_event(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    await bridge_with_world(start_bridge, sim, payloads.world())
    # a restarted sim numbers its events from 0 again, under a new run id
    sim.sensor("r1", keys.COLLISION, payloads.collision(seq=0, stamp=3.0, run="before"))
    sim.sensor("r1", keys.COLLISION, payloads.collision(seq=0, stamp=1.0, run="after"))
    await eventually(lambda: _rows(conn, 2), what="two rows")
    runs = await conn.fetch("SELECT run, seq FROM collision_event ORDER BY id")
    assert [tuple(r) for r in runs] == [("before", 0), ("after", 0)]


async def test_an_event_without_a_run_is_written_as_before(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    await bridge_with_world(start_bridge, sim, payloads.world())
    # a robot that does not resend (no run): every message is its own row, as before
    sim.sensor("r1", keys.COLLISION, payloads.collision(seq=1))
    sim.sensor("r1", keys.COLLISION, payloads.collision(seq=1))
    await eventually(lambda: _rows(conn, 2), what="two rows")
    assert await conn.fetchval("SELECT count(*) FROM collision_event WHERE run IS NULL") == 2


async def _rows(conn: asyncpg.Connection, n: int) -> bool:
    found: int = await conn.fetchval("SELECT count(*) FROM collision_event")
    return found == n

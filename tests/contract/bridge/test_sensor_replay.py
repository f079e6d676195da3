"""Sensor rows a Postgres crash lost after their (asynchronous) commit come back, ids and all.

A real crash loses them only sometimes (it depends on where the WAL writer was), so the
test plays the crash's effect on the data exactly: the newest committed rows vanish, the
id sequence falls back behind them, and the bridge's connections are cut. ``pnav bench
faults`` does it for real (kill -9 of the postmaster).
"""

from __future__ import annotations

import asyncio

import asyncpg
import pytest

from common.contract import keys
from pnav._testing import eventually
from tests.contract.bridge.conftest import BridgeFactory, FakeSim, bridge_with_world
from tests.unit.bridge import payloads

pytestmark = pytest.mark.timeout(60)

_CUT = (
    "SELECT count(pg_terminate_backend(pid)) FROM pg_stat_activity"
    " WHERE application_name = 'pnav-bridge-sensors'"
)


async def _odometry(sim: FakeSim, seqs: range) -> None:
    for seq in seqs:
        sim.sensor("r1", keys.ODOM, payloads.odom(seq=seq))
        await asyncio.sleep(0.02)


async def _until_seq(conn: asyncpg.Connection, seq: int) -> None:
    await eventually(
        lambda: conn.fetchval("SELECT max(seq) = $1 FROM odometry", seq), what=f"seq {seq}"
    )


async def _rows(conn: asyncpg.Connection) -> dict[int, int]:
    """seq -> id of r1's odometry rows."""
    return {r["seq"]: r["id"] for r in await conn.fetch("SELECT seq, id FROM odometry")}


async def test_rows_a_crash_took_return_with_their_ids_before_newer_ones(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge = await bridge_with_world(start_bridge, sim, payloads.world())
    await _odometry(sim, range(10))
    await _until_seq(conn, 9)
    before = await _rows(conn)

    # the crash: seq 6-9 were committed but never reached the disk, nor did the sequence's
    # advance past them; and every connection is gone
    lost = {seq: before[seq] for seq in range(6, 10)}
    await conn.execute("DELETE FROM odometry WHERE seq >= 6")
    await conn.execute("SELECT setval(pg_get_serial_sequence('odometry', 'id'), $1)", before[5])
    assert await conn.fetchval(_CUT) >= 1

    await _odometry(sim, range(10, 40))  # the first write after the cut fails, later reconnect
    await _until_seq(conn, 39)

    after = await _rows(conn)
    assert {seq: after.get(seq) for seq in lost} == lost  # back, under the same ids
    assert bridge.counters.rows_restored[keys.ODOMETRY] == len(lost)
    newer = [after[seq] for seq in range(10, 40) if seq in after]
    assert newer and min(newer) > max(lost.values())  # the sequence moved past them
    assert set(before.items()) <= set(after.items())


async def test_a_cut_without_a_crash_restores_nothing_and_loses_nothing(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge = await bridge_with_world(start_bridge, sim, payloads.world())
    await _odometry(sim, range(5))
    await _until_seq(conn, 4)
    before = await _rows(conn)
    assert await conn.fetchval(_CUT) >= 1
    await _odometry(sim, range(5, 30))
    await _until_seq(conn, 29)
    after = await _rows(conn)
    assert set(before.items()) <= set(after.items())
    assert bridge.counters.rows_restored[keys.ODOMETRY] == 0
    assert len(set(after.values())) == len(after)

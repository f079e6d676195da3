"""The safety layer in the real bridge: a rogue decision cannot drive into what the scan shows."""

from __future__ import annotations

import math
from typing import Any

import asyncpg
import pytest

from common.contract import keys
from pnav._testing import eventually
from tests.contract.bridge.conftest import BridgeFactory, FakeSim, Inbox, command, ready, vel
from tests.unit.bridge import payloads

pytestmark = pytest.mark.timeout(60)


def obstacle(range_m: float, degrees: int, stamp: float, seq: int) -> dict[str, Any]:
    """A scan (beam 0 ahead) with one return at ``range_m``, ``degrees`` counter-clockwise."""
    ranges = [math.inf] * 360
    ranges[degrees % 360] = range_m
    return payloads.scan(seq=seq, stamp=stamp, ranges=ranges)


async def note(conn: asyncpg.Connection, row_id: int) -> asyncpg.Record:
    row: asyncpg.Record = await conn.fetchrow(
        "SELECT safety, sent_linear_mps, sent_angular_rps FROM command2robot WHERE id = $1",
        row_id,
    )
    return row


async def noted(conn: asyncpg.Connection, row_id: int) -> asyncpg.Record:
    """The row's safety note, once the bridge wrote it."""
    row: asyncpg.Record | None = None

    async def written() -> bool:
        nonlocal row
        row = await note(conn, row_id)
        return row["safety"] is not None

    await eventually(written, what=f"the safety note on command {row_id}")
    assert row is not None
    return row


async def sent_for(cmd_vel: Inbox, row_id: int) -> tuple[float, float, int | None]:
    """The cmd_vel of command ``row_id`` (a watchdog stop, id nil, may come first)."""
    while True:
        sent = vel((await cmd_vel.next())[1])
        if sent[2] is not None:
            assert sent[2] == row_id
            return sent


async def test_a_full_speed_command_toward_an_obstacle_is_stopped_and_the_row_says_why(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge, cmd_vel = await ready(start_bridge, sim)
    safety = bridge.commands.safety
    sim.sensor("r1", keys.SCAN, obstacle(0.14, 0, stamp=10.0, seq=1))
    await eventually(lambda: "r1" in safety.scans, what="the scan")

    # a rogue decision: full speed ahead, whatever priority chose it
    rogue = await command(conn, sim, 0.22, 0.3)
    assert vel((await cmd_vel.next())[1]) == (0.0, 0.3, rogue)  # stopped, still turning
    row = await noted(conn, rogue)
    assert row["safety"].startswith("stopped: obstacle 0.14 m ahead at +0 deg")
    assert (row["sent_linear_mps"], row["sent_angular_rps"]) == (0.0, 0.3)
    assert bridge.counters.safety_stopped == 1

    # farther away: slowed to a speed that stops in time
    sim.sensor("r1", keys.SCAN, obstacle(0.17, 0, stamp=10.0, seq=2))
    await eventually(lambda: bool(safety.scans["r1"].x.max() > 0.16), what="the second scan")
    limited = await command(conn, sim, 0.22, 0.0)
    linear, angular, _ = vel((await cmd_vel.next())[1])
    assert 0.05 < linear < 0.22 and angular == 0.0
    row = await noted(conn, limited)
    assert row["safety"].startswith(f"limited to {linear:.3f} m/s: obstacle 0.17 m ahead")
    assert row["sent_linear_mps"] == linear
    assert bridge.counters.safety_limited == 1

    # away from it: sent as decided, nothing written on the row
    away = await command(conn, sim, -0.2, 0.0)
    assert vel((await cmd_vel.next())[1]) == (-0.2, 0.0, away)

    # the scan too old to be evidence (0.6 s of sim time): sent, and the row says unchecked
    sim.clock(10.6)
    await eventually(lambda: bridge.runtime.clock.now() == 10.6, what="the sim clock")
    blind = await command(conn, sim, 0.22, 0.0, stamp=10.6)
    assert await sent_for(cmd_vel, blind) == (0.22, 0.0, blind)
    row = await noted(conn, blind)
    assert row["safety"] == "unchecked: no scan within 0.5 s (newest scan 0.60 s old)"
    assert (await note(conn, away))["safety"] is None
    snapshot = bridge.counters.snapshot()
    assert (snapshot["safety_stopped"], snapshot["safety_limited"]) == (1, 1)
    assert snapshot["safety_unchecked"] == 1

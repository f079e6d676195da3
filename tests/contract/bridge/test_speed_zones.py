"""Speed zones in the real bridge: a zone people add at run time caps the speed sent to a
robot inside it at once, with no restart; the command2robot row keeps what was decided, and
the row's safety note and the counters say what the cap did."""

from __future__ import annotations

import math

import asyncpg
import pytest

from common.contract import keys
from pnav._testing import eventually
from tests.contract.bridge.conftest import BridgeFactory, FakeSim, command, ready
from tests.contract.bridge.test_safety import noted, sent_for
from tests.unit.bridge import payloads

pytestmark = pytest.mark.timeout(60)

ZONE_SQL = (
    "INSERT INTO zone (name, kind, xs, ys, max_speed_mps) VALUES ($1, 'speed_limit', "
    "$2::float8[], $3::float8[], $4)"
)
# round the robot's pose in payloads.odom, (1.5, -2.25)
AROUND = ([1.0, 2.0, 2.0, 1.0], [-3.0, -3.0, -1.0, -1.0])


async def test_a_speed_zone_added_at_run_time_caps_the_speed_sent_at_once(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge, cmd_vel = await ready(start_bridge, sim)
    safety = bridge.commands.safety
    sim.sensor("r1", keys.ODOM, payloads.odom(seq=1, stamp=10.0))
    sim.sensor("r1", keys.SCAN, payloads.scan(seq=1, stamp=10.0, ranges=[math.inf] * 360))
    await eventually(lambda: "r1" in safety.zones.poses, what="the robot's pose")
    await eventually(lambda: "r1" in safety.scans, what="the scan")

    before = await command(conn, sim, 0.22, 0.0)
    assert await sent_for(cmd_vel, before) == (0.22, 0.0, before)  # no zone yet

    # people add a zone round the robot, and notify as the CLI does
    await conn.execute(ZONE_SQL, "dock-aisle", *AROUND, 0.1)
    sim.notifier.notify(keys.ZONE, None, None)
    await eventually(lambda: bool(safety.zones.zones), what="the zone read")
    capped = await command(conn, sim, 0.22, 0.3)
    assert await sent_for(cmd_vel, capped) == (0.1, 0.3, capped)
    row = await noted(conn, capped)
    assert row["safety"] == (
        "limited to 0.1 m/s: speed zone 'dock-aisle' caps 0.1 m/s (0.220 m/s decided)"
    )
    assert row["sent_linear_mps"] == 0.1
    decided = await conn.fetchval("SELECT linear_mps FROM command2robot WHERE id = $1", capped)
    assert decided == 0.22  # the decision's record stays what it decided
    assert bridge.counters.safety_zone_capped == 1 and bridge.counters.safety_limited == 1

    # removed: commands pass again
    await conn.execute("DELETE FROM zone")
    sim.notifier.notify(keys.ZONE, None, None)
    await eventually(lambda: not safety.zones.zones, what="the zone gone")
    after = await command(conn, sim, 0.22, 0.0)
    assert await sent_for(cmd_vel, after) == (0.22, 0.0, after)


async def test_a_zone_written_without_a_notification_applies_within_the_refresh_period(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge, cmd_vel = await ready(start_bridge, sim)
    safety = bridge.commands.safety
    sim.sensor("r1", keys.ODOM, payloads.odom(seq=1, stamp=10.0))
    await eventually(lambda: "r1" in safety.zones.poses, what="the robot's pose")
    await conn.execute(ZONE_SQL, "quiet", *AROUND, 0.05)  # psql: no notification
    await eventually(lambda: bool(safety.zones.zones), what="the zone read on the period")
    capped = await command(conn, sim, 0.2, 0.0)
    assert await sent_for(cmd_vel, capped) == (0.05, 0.0, capped)

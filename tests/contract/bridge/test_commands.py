"""command2robot -> cmd_vel: clamped, with or without a notification; the sim-time watchdog."""

from __future__ import annotations

import asyncio
import math

import asyncpg
import pytest

from common.contract import keys
from tests.contract.bridge.conftest import (
    SETTLE_S,
    BridgeFactory,
    FakeSim,
    command,
    ready,
    vel,
)

pytestmark = pytest.mark.timeout(60)


async def test_a_notified_command_reaches_cmd_vel_clamped_to_the_robot_limits(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge, cmd_vel = await ready(start_bridge, sim, robots=("r1", "r2"))
    await conn.execute("UPDATE robot SET max_linear_mps = 0.5 WHERE robot_id = 'r2'")
    first = await command(conn, sim, 1.0, -5.0)
    key, body = await cmd_vel.next()
    assert key == keys.robot_key("r1", keys.CMD_VEL)
    assert vel(body) == (0.22, -2.84, first)
    assert body["stamp"] == 10.0  # sim time of sending
    assert body["decided_stamp"] == 10.0  # the row's stamp: when the decision was made
    assert set(body) == {"stamp", "linear", "angular", "command_id", "decided_stamp"}

    within = await command(conn, sim, 0.1, 0.5, stamp=9.96)
    _, body = await cmd_vel.next()
    assert vel(body) == (0.1, 0.5, within) and body["decided_stamp"] == 9.96
    other = await command(conn, sim, 0.4, 0.0, robot="r2")  # r2's own limits
    key, body = await cmd_vel.next()
    assert (key, vel(body)) == (keys.robot_key("r2", keys.CMD_VEL), (0.4, 0.0, other))
    # sent once each, not again on every periodic re-read
    assert await cmd_vel.quiet(0.2) == []
    assert bridge.counters.commands_out == 3


async def test_a_command_without_notification_is_found_by_the_periodic_read(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    _, cmd_vel = await ready(start_bridge, sim)
    row_id = await command(conn, None, -0.1, 0.3)
    _, body = await cmd_vel.next(within=2.0)
    assert vel(body) == (-0.1, 0.3, row_id)


async def test_nan_becomes_zero_and_infinity_the_limit(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    _, cmd_vel = await ready(start_bridge, sim)
    row_id = await command(conn, sim, math.nan, math.inf)
    assert vel((await cmd_vel.next())[1]) == (0.0, 2.84, row_id)
    row_id = await command(conn, sim, -math.inf, math.nan)
    assert vel((await cmd_vel.next())[1]) == (-0.22, 0.0, row_id)


async def test_the_watchdog_stops_the_robot_once_after_half_a_second_of_sim_time(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge, cmd_vel = await ready(start_bridge, sim)
    row_id = await command(conn, sim, 0.2, 0.0)
    assert vel((await cmd_vel.next())[1]) == (0.2, 0.0, row_id)

    sim.clock(10.3)  # 0.3 s of sim time without a fresh command: keep going
    assert await cmd_vel.quiet(0.2) == []
    sim.clock(10.5)
    key, body = await cmd_vel.next(within=1.0)
    assert (key, vel(body)) == (keys.robot_key("r1", keys.CMD_VEL), (0.0, 0.0, None))
    assert body["stamp"] == 10.5
    assert bridge.counters.watchdog_stops == 1
    for stamp in (11.0, 12.0, 13.0):  # once, not on every tick
        sim.clock(stamp)
    assert await cmd_vel.quiet(0.3) == []

    # a fresh command resumes, and re-arms the watchdog
    row_id = await command(conn, sim, 0.1, 0.1, stamp=13.0)
    assert vel((await cmd_vel.next())[1]) == (0.1, 0.1, row_id)
    sim.clock(13.6)
    assert vel((await cmd_vel.next(within=1.0))[1]) == (0.0, 0.0, None)
    assert bridge.counters.watchdog_stops == 2


async def test_wall_time_alone_never_trips_the_watchdog(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    """A paused sim (its clock not advancing) keeps its last command: time is sim time."""
    _, cmd_vel = await ready(start_bridge, sim)
    await command(conn, sim, 0.2, 0.0)
    await cmd_vel.next()
    assert await cmd_vel.quiet(0.8) == []


async def test_every_robot_is_sent_a_stop_on_shutdown(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge, cmd_vel = await ready(start_bridge, sim, robots=("r1", "r2"))
    await command(conn, sim, 0.2, 0.0)
    await cmd_vel.next()
    await bridge.stop()
    stops = [await cmd_vel.next(), await cmd_vel.next()]
    assert sorted(key for key, _ in stops) == [
        keys.robot_key("r1", keys.CMD_VEL),
        keys.robot_key("r2", keys.CMD_VEL),
    ]
    assert all(vel(body) == (0.0, 0.0, None) for _, body in stops)


async def test_an_old_command_found_at_start_up_is_not_replayed(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    await conn.execute("INSERT INTO robot (robot_id) VALUES ('r1')")
    await command(conn, None, 0.2, 0.0, stamp=1.0)  # from a previous run
    sim.clock(100.0)
    cmd_vel = sim.listen(keys.robot_watch(keys.CMD_VEL))
    await asyncio.sleep(SETTLE_S)
    bridge = await start_bridge()
    assert await cmd_vel.quiet(0.3) == []
    assert bridge.counters.commands_out == 0
    row_id = await command(conn, sim, 0.1, 0.0, stamp=100.0)
    assert vel((await cmd_vel.next())[1]) == (0.1, 0.0, row_id)

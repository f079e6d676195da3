"""The shared contract reads and writes, against a real database."""

from __future__ import annotations

import math

import asyncpg
import numpy as np
import pytest

from common import bus
from common.config import ZenohSettings
from common.contract import recommendations, records
from common.db import Database, create_pool


@pytest.fixture
async def seeded(conn: asyncpg.Connection) -> asyncpg.Connection:
    await conn.execute("INSERT INTO robot (robot_id) VALUES ('r1'), ('r2')")
    await conn.execute(
        "INSERT INTO odometry (robot_id, stamp, x, y, yaw, linear_mps, angular_rps) VALUES "
        "('r1', 1.0, 0, 0, 0, 0, 0), ('r1', 2.0, 1.5, -0.5, 0.3, 0.2, 0.1)"
    )
    ranges = [math.inf] * 360
    ranges[0], ranges[90], ranges[270], ranges[180] = 0.5, 1.0, 2.0, 0.12
    await conn.execute(
        "INSERT INTO laser_scan (robot_id, stamp, angle_min, angle_increment, range_min, "
        "range_max, ranges) VALUES ('r1', 2.0, 0, $1, 0.12, 3.5, $2)",
        2 * math.pi / 360,
        ranges,
    )
    return conn


async def test_newest_rows_per_robot(seeded: asyncpg.Connection) -> None:
    odom = await records.newest_odometry(seeded, "r1")
    assert odom is not None and (odom.stamp, odom.x, odom.yaw) == (2.0, 1.5, 0.3)
    assert await records.newest_odometry(seeded, "r2") is None
    assert [r.robot_id for r in await records.robots(seeded)] == ["r1", "r2"]


async def test_newest_scan_and_odometry_in_one_read(seeded: asyncpg.Connection) -> None:
    scan, odom = await records.newest_scan_and_odometry(seeded, "r1")
    alone = await records.newest_scan(seeded, "r1")
    assert scan is not None and alone is not None
    assert (scan.id, scan.stamp, scan.angle_increment) == (
        alone.id,
        alone.stamp,
        alone.angle_increment,
    )
    assert np.array_equal(scan.ranges, alone.ranges)
    assert odom == await records.newest_odometry(seeded, "r1")
    assert scan is not None and scan.ranges.dtype == np.float32 and len(scan.ranges) == 360
    assert await records.newest_scan_and_odometry(seeded, "r2") == (None, None)
    await seeded.execute("DELETE FROM odometry")
    scan, odom = await records.newest_scan_and_odometry(seeded, "r1")
    assert scan is not None and odom is None


async def test_scan_sectors_use_angles_relative_to_the_heading(seeded: asyncpg.Connection) -> None:
    scan = await records.newest_scan(seeded, "r1")
    assert scan is not None and scan.ranges.dtype == np.float32
    assert scan.sector_min(-0.1, 0.1) == pytest.approx(0.5)  # beam 0: straight ahead
    assert scan.sector_min(1.4, 1.7) == pytest.approx(1.0)  # beam 90: left
    assert scan.sector_min(-1.7, -1.4) == pytest.approx(2.0)  # beam 270: right, wrapped
    assert scan.sector_min(2.0, 3.0) == math.inf
    # a hit at range_min (anything closer reads range_min) is the most important one to keep
    assert scan.sector_min(3.1, math.pi) == pytest.approx(0.12)


async def test_strategies_and_active_strategy(seeded: asyncpg.Connection) -> None:
    table = await records.strategies(seeded)
    assert table["GOTO_DIRECT"].controller_scenarios == ("safety_stop",)
    assert table["IDLE"].planner_scenario is None
    await seeded.execute(
        "INSERT INTO active_strategy (robot_id, strategy_code) VALUES ('r1', 'CHARGE')"
    )
    active = await records.active_strategies(seeded)
    assert list(active) == ["r1"]
    assert active["r1"].strategy.params["target"] == "nearest_charger"


async def test_recommendations_carry_expiry_and_provenance(
    db_url: str, zenoh_settings: ZenohSettings, seeded: asyncpg.Connection
) -> None:
    session = bus.open_session(zenoh_settings)
    db = Database(await create_pool(db_url), bus.Notifier(session))
    try:
        rid = await recommendations.recommend_velocity(
            db,
            "r1",
            source="avoid_left",
            priority=50,
            linear=0.0,
            angular=1.0,
            stamp=10.0,
            ttl_s=0.5,
            reason="obstacle on the right",
            inputs={"laser_scan": 7},
        )
        sid = await recommendations.recommend_system(
            db,
            "r1",
            source="battery_check",
            priority=50,
            command="CMD_BATTSAVE",
            stamp=10.0,
            ttl_s=2.0,
            reason="low",
        )
    finally:
        db.notifier.close()
        await db.close()
        session.close()
    rows = {r["id"]: r for r in await seeded.fetch("SELECT * FROM command_recommendation")}
    assert rows[rid]["expires_stamp"] == 10.5 and rows[rid]["inputs"] == {"laser_scan": 7}
    assert rows[sid]["kind"] == "system" and rows[sid]["system_command"] == "CMD_BATTSAVE"

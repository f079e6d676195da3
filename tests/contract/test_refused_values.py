"""Migration 3: the database refuses non-finite and absurd numbers, whoever writes them.

Each test speaks plain SQL through asyncpg as a foreign client would (no proactive-nav
helper), so what it shows holds for a replacement service in any language.
"""

from __future__ import annotations

import math
from collections.abc import AsyncIterator
from typing import Any

import asyncpg
import pytest

from common.contract import limits
from common.contract.migrate import apply_migrations, contract_migrations

NAN, INF = math.nan, math.inf

GOAL_SQL = "INSERT INTO goal (robot_id, x, y, tolerance_m, stamp) VALUES ('r1', $1, $2, $3, $4)"
REC_SQL = """
INSERT INTO command_recommendation (robot_id, kind, source, priority, linear_mps, angular_rps,
    system_command, stamp, expires_stamp)
VALUES ('r1', $1, 'probe', $2, $3, $4, $5, $6, $7)
"""
C2R_SQL = """
INSERT INTO command2robot (robot_id, stamp, linear_mps, angular_rps) VALUES ('r1', $1, $2, $3)
"""
ODOM_SQL = """
INSERT INTO odometry (robot_id, stamp, x, y, yaw, linear_mps, angular_rps)
VALUES ('r1', $1, $2, 0, 0, 0, 0)
"""
SCAN_SQL = """
INSERT INTO laser_scan (robot_id, stamp, angle_min, angle_increment, range_min, range_max,
    ranges)
VALUES ('r1', $1, 0, 0.0175, 0.12, $2, $3)
"""
BATTERY_SQL = """
INSERT INTO battery (robot_id, stamp, energy_wh, capacity_wh, percentage)
VALUES ('r1', $1, $2, 19.98, 50)
"""


@pytest.fixture
async def client(db_url: str) -> AsyncIterator[asyncpg.Connection]:
    # A bare asyncpg connection: no codecs, no helpers, as any foreign client has.
    conn = await asyncpg.connect(db_url)
    await conn.execute("INSERT INTO robot (robot_id) VALUES ('r1')")
    try:
        yield conn
    finally:
        await conn.close()


async def refused(conn: asyncpg.Connection, sql: str, *args: Any) -> str:
    """Run ``sql``; it must fail with a check violation. Return the constraint's name."""
    with pytest.raises(asyncpg.CheckViolationError) as caught:
        await conn.execute(sql, *args)
    name = caught.value.constraint_name
    assert name
    return str(name)


# -- goal --------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("x", "y", "tolerance", "stamp", "constraint"),
    [
        (NAN, 1.0, 0.15, None, "goal_xy_bounded"),
        (1.0, NAN, 0.15, None, "goal_xy_bounded"),
        (INF, 0.0, 0.15, None, "goal_xy_bounded"),
        (0.0, -INF, 0.15, None, "goal_xy_bounded"),
        (1e308, 0.0, 0.15, None, "goal_xy_bounded"),
        (100_000.001, 0.0, 0.15, None, "goal_xy_bounded"),
        (0.0, -100_000.001, 0.15, None, "goal_xy_bounded"),
        (1.0, 1.0, NAN, None, "goal_tolerance_bounded"),
        (1.0, 1.0, INF, None, "goal_tolerance_bounded"),
        (1.0, 1.0, -1.0, None, "goal_tolerance_bounded"),
        (1.0, 1.0, 0.0, None, "goal_tolerance_bounded"),
        (1.0, 1.0, 100.5, None, "goal_tolerance_bounded"),
        (1.0, 1.0, 0.15, NAN, "goal_stamps_finite"),
        (1.0, 1.0, 0.15, -INF, "goal_stamps_finite"),
    ],
)
async def test_a_goal_with_a_bad_number_is_refused(
    client: asyncpg.Connection,
    x: float,
    y: float,
    tolerance: float,
    stamp: float | None,
    constraint: str,
) -> None:
    assert await refused(client, GOAL_SQL, x, y, tolerance, stamp) == constraint
    assert await client.fetchval("SELECT count(*) FROM goal") == 0


async def test_sane_goals_pass_at_the_bounds(client: asyncpg.Connection) -> None:
    for x, y, tolerance, stamp in [
        (100_000.0, -100_000.0, 100.0, 0.0),
        (-3.5, 2.0, 0.001, None),
        (1.0, 1.0, 0.15, 1234.5),
    ]:
        await client.execute("UPDATE goal SET status = 'superseded' WHERE status = 'active'")
        await client.execute(GOAL_SQL, x, y, tolerance, stamp)
    assert await client.fetchval("SELECT count(*) FROM goal") == 3


async def test_the_planner_cannot_mark_a_goal_finished_at_a_nan_stamp(
    client: asyncpg.Connection,
) -> None:
    await client.execute(GOAL_SQL, 1.0, 1.0, 0.15, 0.0)
    update = "UPDATE goal SET status = 'reached', finished_stamp = $1"
    assert await refused(client, update, NAN) == "goal_stamps_finite"
    await client.execute(update, 12.5)


# -- strategy -----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "params",
    ['{"avoid_distance_m": 1e400}', '{"scan_max_age_s": -2e6}', "[1, 2]", '"GOTO"', "3"],
)
async def test_strategy_params_must_be_an_object_of_sane_numbers(
    client: asyncpg.Connection, params: str
) -> None:
    insert = "INSERT INTO strategy (code, planner_scenario, params) VALUES ('MINE', NULL, $1)"
    assert await refused(client, insert, params) == "strategy_params_sane"
    # NOT VALID still guards every update, built-in strategies included
    update = "UPDATE strategy SET params = $1 WHERE code = 'GOTO_AVOID'"
    assert await refused(client, update, params) == "strategy_params_sane"


async def test_sane_strategy_params_pass(client: asyncpg.Connection) -> None:
    await client.execute(
        "INSERT INTO strategy (code, planner_scenario, params) VALUES ('MINE', 'turn_then_move', "
        """'{"target": "goal", "avoid_distance_m": 0.4, "scan_max_age_s": 1e6, """
        """"battery_reserve_wh": -1e6}')"""
    )
    assert await client.fetchval("SELECT count(*) FROM strategy WHERE code = 'MINE'") == 1


# -- command_recommendation ----------------------------------------------------------------------
def robot_rec(
    priority: int = 10,
    linear: float = 0.2,
    angular: float = 0.0,
    stamp: float = 10.0,
    expires: float = 10.5,
) -> tuple[Any, ...]:
    return ("robot", priority, linear, angular, None, stamp, expires)


def system_rec(priority: int = 60, stamp: float = 10.0, expires: float = 12.0) -> tuple[Any, ...]:
    return ("system", priority, None, None, "CMD_BATTSAVE", stamp, expires)


@pytest.mark.parametrize(
    ("row", "constraint"),
    [
        (robot_rec(linear=NAN), "command_recommendation_velocity_bounded"),
        (robot_rec(angular=NAN), "command_recommendation_velocity_bounded"),
        (robot_rec(linear=INF), "command_recommendation_velocity_bounded"),
        (robot_rec(angular=-INF), "command_recommendation_velocity_bounded"),
        (robot_rec(linear=10.01), "command_recommendation_velocity_bounded"),
        (robot_rec(linear=-10.01), "command_recommendation_velocity_bounded"),
        (robot_rec(angular=20.01), "command_recommendation_velocity_bounded"),
        (robot_rec(stamp=NAN, expires=NAN), "command_recommendation_stamps_finite"),
        (robot_rec(stamp=-INF), "command_recommendation_stamps_finite"),
        (robot_rec(expires=INF), "command_recommendation_stamps_finite"),
        (robot_rec(priority=2147483647), "command_recommendation_priority_bounded"),
        (robot_rec(priority=1001, linear=0.0), "command_recommendation_priority_bounded"),
        (robot_rec(priority=-1), "command_recommendation_priority_bounded"),
        # the safety band only stops travel: nothing that outranks safety_stop can drive
        (robot_rec(priority=100, linear=0.2), "command_recommendation_safety_band"),
        (robot_rec(priority=1000, linear=-0.01), "command_recommendation_safety_band"),
        (system_rec(priority=100), "command_recommendation_safety_band"),
    ],
)
async def test_a_bad_recommendation_is_refused(
    client: asyncpg.Connection, row: tuple[Any, ...], constraint: str
) -> None:
    assert await refused(client, REC_SQL, *row) == constraint
    assert await client.fetchval("SELECT count(*) FROM command_recommendation") == 0


async def test_every_shipped_priority_and_the_bounds_pass(client: asyncpg.Connection) -> None:
    rows = [
        robot_rec(priority=10, linear=0.22, angular=-2.84),  # turn_then_move
        robot_rec(priority=50, linear=0.05, angular=1.0),  # avoid_left, avoid_right
        robot_rec(priority=100, linear=0.0, angular=0.8),  # safety_stop
        robot_rec(priority=100, linear=-0.0, angular=0.0),  # safety_stop, boxed in
        system_rec(priority=60),  # battery_check
        system_rec(priority=50),  # charge_complete
        robot_rec(priority=0, linear=10.0, angular=-20.0),
        robot_rec(priority=99, linear=-10.0, angular=20.0),
        robot_rec(priority=1000, linear=0.0, angular=20.0),
        robot_rec(stamp=0.0, expires=0.0),
        robot_rec(stamp=-5.0, expires=1e9),
    ]
    for row in rows:
        await client.execute(REC_SQL, *row)
    assert await client.fetchval("SELECT count(*) FROM command_recommendation") == len(rows)


# -- command2robot --------------------------------------------------------------------------
async def test_command2robot_stays_open_to_the_bridge_guard(client: asyncpg.Connection) -> None:
    # no CHECK here on purpose: the bridge's own NaN/limit guard is tested through this table
    await client.execute(C2R_SQL, 10.0, NAN, INF)


# -- sensor rows and the world ----------------------------------------------------------------
async def test_sensor_rows_must_be_finite_but_a_scan_keeps_infinity(
    client: asyncpg.Connection,
) -> None:
    assert await refused(client, ODOM_SQL, NAN, 0.0) == "odometry_finite"
    assert await refused(client, ODOM_SQL, 1.0, INF) == "odometry_finite"
    await client.execute(ODOM_SQL, 1.0, -3.0)
    ranges = [INF] * 359 + [0.5]
    assert await refused(client, SCAN_SQL, NAN, 3.5, ranges) == "laser_scan_finite"
    assert await refused(client, SCAN_SQL, 1.0, INF, ranges) == "laser_scan_finite"
    await client.execute(SCAN_SQL, 1.0, 3.5, ranges)  # Infinity: nothing within range_max
    # energy_wh >= 0 alone let NaN through (NaN sorts above every number)
    assert await refused(client, BATTERY_SQL, 1.0, NAN) == "battery_finite"
    assert await refused(client, BATTERY_SQL, INF, 5.0) == "battery_finite"
    await client.execute(BATTERY_SQL, 1.0, 5.0)
    collision = (
        "INSERT INTO collision_event (robot_id, stamp, other, x, y) VALUES ('r1', $1, 'w', 0, 0)"
    )
    assert await refused(client, collision, NAN) == "collision_event_finite"
    await client.execute(collision, 1.0)


async def test_world_rows_must_be_finite(client: asyncpg.Connection) -> None:
    update = "UPDATE robot SET max_linear_mps = $1 WHERE robot_id = 'r1'"
    assert await refused(client, update, NAN) == "robot_limits_finite"
    await client.execute(update, 0.5)
    await client.execute(
        "INSERT INTO map (map_id, resolution_m, origin_x, origin_y, width, height, grid) "
        "VALUES ('m', 0.05, 0, 0, 1, 1, '\\x00')"
    )
    assert (
        await refused(client, "UPDATE map SET resolution_m = $1", NAN) == "map_finite"
    )  # resolution_m > 0 alone let NaN through
    station = (
        "INSERT INTO charging_station (station_id, map_id, x, y, radius_m, charge_power_w) "
        "VALUES ('c', 'm', 1, 1, $1, 10)"
    )
    assert await refused(client, station, NAN) == "charging_station_finite"
    await client.execute(station, 0.3)


async def test_active_strategy_and_system_command_stamps_must_be_finite(
    client: asyncpg.Connection,
) -> None:
    active = (
        "INSERT INTO active_strategy (robot_id, strategy_code, stamp) VALUES ('r1', 'IDLE', $1)"
    )
    assert await refused(client, active, NAN) == "active_strategy_stamp_finite"
    await client.execute(active, None)
    system = "INSERT INTO system_command (robot_id, command, stamp) VALUES ('r1', 'CMD_RESUME', $1)"
    assert await refused(client, system, INF) == "system_command_stamp_finite"
    await client.execute(system, 3.0)


# -- common.contract.limits (what tools check first) is what the database enforces ------------
async def test_the_python_limits_are_the_database_bounds(client: asyncpg.Connection) -> None:
    def above(v: float) -> float:
        return math.nextafter(v, INF)

    g, t = limits.GOAL_MAX_ABS_M, limits.GOAL_MAX_TOLERANCE_M
    await client.execute(GOAL_SQL, g, -g, t, None)
    await refused(client, GOAL_SQL, above(g), 0.0, 0.15, None)
    await refused(client, GOAL_SQL, 0.0, 0.0, above(t), None)
    v, w = limits.MAX_ABS_LINEAR_MPS, limits.MAX_ABS_ANGULAR_RPS
    await client.execute(REC_SQL, *robot_rec(linear=-v, angular=w))
    await refused(client, REC_SQL, *robot_rec(linear=above(v)))
    await refused(client, REC_SQL, *robot_rec(angular=above(w)))
    top, safety = limits.MAX_PRIORITY, limits.SAFETY_PRIORITY
    await client.execute(REC_SQL, *robot_rec(priority=top, linear=0.0))
    await client.execute(REC_SQL, *robot_rec(priority=limits.MIN_PRIORITY))
    await client.execute(REC_SQL, *robot_rec(priority=safety - 1, linear=v))
    await refused(client, REC_SQL, *robot_rec(priority=top + 1, linear=0.0))
    await refused(client, REC_SQL, *robot_rec(priority=limits.MIN_PRIORITY - 1))
    await refused(client, REC_SQL, *robot_rec(priority=safety, linear=0.01))
    insert = "INSERT INTO strategy (code, params) VALUES ($1, $2)"
    p = limits.MAX_ABS_PARAM
    await client.execute(insert, "AT_BOUND", f'{{"k": {-p!r}}}')
    await refused(client, insert, "BEYOND", f'{{"k": {above(p)!r}}}')


# -- the migration on a database that already holds bad rows ------------------------------------
async def test_migration_3_applies_on_top_of_rows_it_would_refuse(empty_db_url: str) -> None:
    conn = await asyncpg.connect(empty_db_url)
    try:
        migrations = contract_migrations()
        assert [m.version for m in migrations[:3]] == [1, 2, 3]
        await apply_migrations(conn, migrations[:2])
        await conn.execute("INSERT INTO robot (robot_id, max_linear_mps) VALUES ('r1', 'NaN')")
        await conn.execute(GOAL_SQL, NAN, 1.0, 0.15, None)
        await conn.execute("UPDATE goal SET status = 'failed'")
        await conn.execute(GOAL_SQL, 2.0, 1.0, 0.15, None)
        await conn.execute(REC_SQL, *robot_rec(linear=NAN))
        await conn.execute(REC_SQL, *robot_rec(priority=2147483647, linear=0.0))
        await conn.execute(REC_SQL, *robot_rec())
        await conn.execute(ODOM_SQL, NAN, 0.0)
        await conn.execute(ODOM_SQL, 1.0, 0.0)

        assert await apply_migrations(conn) == [m.version for m in migrations[2:]]

        assert await conn.fetchval("SELECT array_agg(x) FROM goal") == [2.0]
        assert await conn.fetchval("SELECT count(*) FROM command_recommendation") == 1
        assert await conn.fetchval("SELECT count(*) FROM odometry") == 1
        # the robot row stays (deleting it would cascade); new writes to it are checked
        assert math.isnan(await conn.fetchval("SELECT max_linear_mps FROM robot"))
        with pytest.raises(asyncpg.CheckViolationError):
            await conn.execute("UPDATE robot SET max_linear_mps = 'Infinity'")
    finally:
        await conn.close()

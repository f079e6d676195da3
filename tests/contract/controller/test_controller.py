"""The controller against Postgres and Zenoh, fed as a foreign client would feed it.

Every assertion is about rows of command_recommendation: source, priority, velocity, stamp
and expiry (CONTRACT.md, "Conventions the shipped scenarios follow"), and the scan the row
says it was derived from (``inputs.laser_scan``).
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Awaitable, Callable
from functools import partial

import asyncpg
import pytest

from common.config import EngineSettings, LeaseSettings, ServiceConfig, ZenohSettings
from common.contract import keys
from pnav._testing import running_service
from tests.contract.conftest import split_between
from tests.contract.controller.conftest import BEAMS, ROBOT, Feeder, Obstacle, eventually

AVOID_SOURCES = ("avoid_left", "avoid_right")
RIGHT = (-40.0, -20.0, 0.30)  # front-right, closer than the avoid distance
AHEAD = (-8.0, 8.0, 0.14)  # dead ahead, inside footprint 0.105 m + margin
PERIOD_S = 0.2  # the lidar's 5 Hz


async def scans_until(
    feeder: Feeder, obstacles: tuple[Obstacle, ...], *sources: str, limit_s: float = 15.0
) -> list[asyncpg.Record]:
    """Write a scan every 0.2 s, as the bridge does, until one of ``sources`` recommends."""

    async def check() -> list[asyncpg.Record]:
        await feeder.scan(*obstacles)
        await asyncio.sleep(PERIOD_S)
        return await feeder.recommendations(*sources)

    return await eventually(check, f"a recommendation from {sources}", limit_s)


async def scans_for(feeder: Feeder, obstacles: tuple[Obstacle, ...], seconds: float) -> list[int]:
    ids = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        ids.append(await feeder.scan(*obstacles))
        await asyncio.sleep(PERIOD_S)
    return ids


def assert_convention(row: asyncpg.Record, priority: int) -> None:
    assert row["kind"] == "robot" and row["priority"] == priority
    assert row["expires_stamp"] - row["stamp"] == pytest.approx(0.5)
    assert row["inputs"]["scan_stamp"] == pytest.approx(row["stamp"])
    assert row["reason"]


async def test_goto_avoid_turns_left_away_from_an_obstacle_on_the_right(
    feeder: Feeder, controller: None
) -> None:
    await feeder.odometry(0.0)
    await feeder.set_strategy("GOTO_AVOID")
    rows = await scans_until(feeder, (RIGHT,), "avoid_left")
    row = rows[0]
    assert_convention(row, 50)
    assert row["angular_rps"] > 0 and 0 <= row["linear_mps"] <= 0.22
    stamp = await feeder.conn.fetchval(
        "SELECT stamp FROM laser_scan WHERE id = $1", row["inputs"]["laser_scan"]
    )
    assert row["stamp"] == pytest.approx(stamp)
    await asyncio.sleep(0.5)
    # Nothing contradicts it: no avoid_right, and no safety_stop for a robot standing still.
    assert await feeder.recommendations("avoid_right", "safety_stop") == []
    # Once per scan: no scan was recommended on twice by avoid_left.
    used = [r["inputs"]["laser_scan"] for r in await feeder.recommendations("avoid_left")]
    assert len(used) == len(set(used))


async def test_goto_direct_does_not_avoid_but_safety_stop_still_stops(
    feeder: Feeder, controller: None
) -> None:
    await feeder.odometry(0.15)  # driving forward
    await feeder.set_strategy("GOTO_DIRECT")
    rows = await scans_until(feeder, (AHEAD, RIGHT), "safety_stop")
    assert_convention(rows[0], 100)
    assert rows[0]["linear_mps"] == 0.0
    assert abs(rows[0]["angular_rps"]) <= 2.84
    await scans_for(feeder, (AHEAD, RIGHT), 1.0)
    assert await feeder.recommendations(*AVOID_SOURCES) == []


async def test_a_strategy_switch_changes_the_scenarios_at_run_time(
    feeder: Feeder, controller: None
) -> None:
    obstacles = ((-25.0, -15.0, 0.14),)  # front-right, in the path: both families fire
    await feeder.odometry(0.15)
    await feeder.set_strategy("GOTO_AVOID")
    await scans_until(feeder, obstacles, "avoid_left")
    await scans_until(feeder, obstacles, "safety_stop")

    await feeder.set_strategy("GOTO_DIRECT")

    async def only_safety_stop_for_three_scans_in_a_row() -> bool:
        streak = 0
        deadline = time.monotonic() + 15.0
        while streak < 3 and time.monotonic() < deadline:
            scan_id = await feeder.scan(*obstacles)
            await eventually(partial(feeder.sources_for, scan_id), "a recommendation", 10.0)
            await asyncio.sleep(0.3)  # let any other scenario have its say on this scan
            streak = streak + 1 if await feeder.sources_for(scan_id) == {"safety_stop"} else 0
        return streak >= 3

    assert await only_safety_stop_for_three_scans_in_a_row()

    await feeder.set_strategy("GOTO_AVOID")
    newest = max(r["id"] for r in await feeder.recommendations())

    async def avoid_left_again() -> bool:
        await feeder.scan(*obstacles)
        await asyncio.sleep(PERIOD_S)
        return any(r["id"] > newest for r in await feeder.recommendations("avoid_left"))

    await eventually(avoid_left_again, "avoid_left after switching back")


async def test_a_strategy_inserted_at_run_time_is_followed_with_its_params(
    feeder: Feeder, controller: None
) -> None:
    await feeder.odometry(0.0)
    params = {"avoid_distance_m": 0.8, "avoid_linear_mps": 0.02}
    await feeder.add_strategy("CAUTIOUS", ["avoid_right", "no_such_scenario"], params)
    await feeder.set_strategy("CAUTIOUS")
    rows = await scans_until(feeder, ((20.0, 40.0, 0.6),), "avoid_right")  # beyond the default
    assert_convention(rows[0], 50)
    assert rows[0]["angular_rps"] < 0 and rows[0]["linear_mps"] == pytest.approx(0.02)
    assert await feeder.recommendations("avoid_left", "safety_stop") == []


async def test_idle_recommends_nothing(feeder: Feeder, controller: None) -> None:
    await feeder.odometry(0.15)
    await feeder.set_strategy("IDLE")
    await scans_for(feeder, (AHEAD, RIGHT), 1.5)
    assert await feeder.recommendations() == []
    # The same scans under GOTO_AVOID are recommended on: the silence was IDLE's doing.
    await feeder.set_strategy("GOTO_AVOID")
    await scans_until(feeder, (AHEAD, RIGHT), "safety_stop")


async def test_a_stale_scan_gets_no_recommendation(feeder: Feeder, controller: None) -> None:
    await feeder.odometry(0.15)
    await feeder.set_strategy("GOTO_AVOID")
    stale = []
    end = time.monotonic() + 1.5
    while time.monotonic() < end:
        stale.append(await feeder.scan(AHEAD, RIGHT, age_s=2.0))
        await asyncio.sleep(PERIOD_S)
    assert await feeder.recommendations() == []
    rows = await scans_until(feeder, (AHEAD, RIGHT), "safety_stop")
    assert rows[0]["inputs"]["laser_scan"] not in stale
    assert not {r["inputs"]["laser_scan"] for r in await feeder.recommendations()} & set(stale)


async def test_two_replicas_split_the_robots_and_each_scan_is_recommended_on_once(
    feeder: Feeder, db_url: str, zenoh_settings: ZenohSettings
) -> None:
    from services.controller.service import ControllerService

    robots = [ROBOT, "r2", "r3", "r4"]
    for robot in robots[1:]:
        await feeder.conn.execute("INSERT INTO robot (robot_id, world) VALUES ($1, 'test')", robot)
        feeder.notifier.notify(keys.ROBOT, robot, None)
    await feeder.conn.executemany(
        "INSERT INTO active_strategy (robot_id, strategy_code, source) "
        "VALUES ($1, 'GOTO_DIRECT', 'user')",
        [(robot,) for robot in robots],
    )
    feeder.notifier.notify(keys.ACTIVE_STRATEGY, None, None)

    for robot in robots:  # driving forward
        await feeder.conn.execute(
            "INSERT INTO odometry (robot_id, stamp, x, y, yaw, linear_mps, angular_rps) "
            "VALUES ($1, $2, 0, 0, 0, 0.15, 0)",
            robot,
            feeder.now(),
        )
    ahead = [0.14 if beam <= 8 or beam >= BEAMS - 8 else math.inf for beam in range(BEAMS)]

    async def scans() -> list[int]:  # an obstacle dead ahead of every robot: safety_stop
        ids = []
        for robot in robots:
            row_id = await feeder.conn.fetchval(
                "INSERT INTO laser_scan (robot_id, stamp, angle_min, angle_increment, "
                "range_min, range_max, ranges) VALUES ($1, $2, 0, $3, 0.12, 3.5, $4) "
                "RETURNING id",
                robot,
                feeder.now(),
                2 * math.pi / BEAMS,
                ahead,
            )
            feeder.notifier.notify(keys.LASER_SCAN, robot, row_id)
            ids.append(row_id)
        return ids

    def config(instance: str) -> ServiceConfig:
        return ServiceConfig(
            service="controller",
            database_url=db_url,
            zenoh=zenoh_settings,
            engine=EngineSettings(period_s=0.05),
            leases=LeaseSettings(period_s=0.2, timeout_s=2.0),
            stats_period_s=30.0,
            instance=instance,
        )

    async with (
        running_service(ControllerService, config("controller-a")) as a,
        running_service(ControllerService, config("controller-b")) as b,
    ):
        await split_between([a, b], robots)
        await scans_for_all(scans, 1.0)  # past any hand-over
        ids = await scans_for_all(scans, 1.5)
        await asyncio.sleep(0.5)  # the last scans' turn
        shares = await split_between([a, b], robots)
    rows = await feeder.conn.fetch(
        "SELECT (inputs->>'laser_scan')::bigint AS scan, count(*) AS n FROM command_recommendation"
        " WHERE source = 'safety_stop' AND (inputs->>'laser_scan')::bigint = ANY($1::bigint[])"
        " GROUP BY 1",
        ids,
    )
    counts = {r["scan"]: r["n"] for r in rows}
    # Every robot is recommended on (most scans), and no scan twice: one replica per robot.
    assert max(counts.values()) == 1, counts
    assert len(counts) >= len(ids) // 2, (len(counts), len(ids))
    served = await feeder.conn.fetch(
        "SELECT DISTINCT robot_id FROM laser_scan WHERE id = ANY($1::bigint[])",
        list(counts),
    )
    assert {r["robot_id"] for r in served} == set(robots)
    assert all(len(share) == 2 for share in shares), shares


async def scans_for_all(write: Callable[[], Awaitable[list[int]]], seconds: float) -> list[int]:
    ids: list[int] = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        ids += await write()
        await asyncio.sleep(PERIOD_S)
    return ids

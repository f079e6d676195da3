"""The shipped controller with the dwa scenario alone (pnav_local, found through its entry
point), against Postgres and Zenoh, fed as a foreign client would: a strategy naming dwa,
a planned_path row, odometry and scans. Assertions are on command_recommendation rows."""

from __future__ import annotations

import asyncio
import itertools
import math
from collections.abc import AsyncIterator
from pathlib import Path

import asyncpg
import pytest

from common.config import EngineSettings, ServiceConfig, ZenohSettings
from common.contract import keys
from pnav._testing import running_service
from tests.contract.controller.conftest import ROBOT, Feeder, Obstacle, eventually

PERIOD_S = 0.2


@pytest.fixture
async def shipped_controller(
    db_url: str, zenoh_settings: ZenohSettings, tmp_path: Path
) -> AsyncIterator[None]:
    from services.controller.service import ControllerService

    config = ServiceConfig(
        service="controller",
        database_url=db_url,
        zenoh=zenoh_settings,
        engine=EngineSettings(period_s=0.05),
        stats_period_s=30.0,
        instance="controller-under-test",
    )
    async with running_service(ControllerService, config, settle_s=0.5):
        yield


async def publish_path(feeder: Feeder, xs: list[float], ys: list[float]) -> int:
    points = list(zip(xs, ys, strict=True))
    length = sum(math.dist(a, b) for a, b in itertools.pairwise(points))
    row_id: int = await feeder.conn.fetchval(
        "INSERT INTO planned_path (robot_id, stamp, target, target_x, target_y, xs, ys, "
        "length_m) VALUES ($1, $2, $3, $4, $5, $6, $7, $8) RETURNING id",
        ROBOT,
        feeder.now(),
        "goal" if xs else "none",
        xs[-1] if xs else None,
        ys[-1] if ys else None,
        xs,
        ys,
        length,
    )
    feeder.notifier.notify(keys.PLANNED_PATH, ROBOT, row_id)
    return row_id


async def dwa_rows(feeder: Feeder, *obstacles: Obstacle, after: int = 0) -> list[asyncpg.Record]:
    """Scans every 0.2 s (and odometry at rest) until dwa recommends after row ``after``."""

    async def check() -> list[asyncpg.Record]:
        await feeder.odometry(0.0)
        await feeder.scan(*obstacles)
        await asyncio.sleep(PERIOD_S)
        return [r for r in await feeder.recommendations("dwa") if r["id"] > after]

    return await eventually(check, "a dwa recommendation")


@pytest.fixture
async def fast(feeder: Feeder) -> Feeder:
    await feeder.add_strategy("DWA_ONLY", ["dwa"], {})
    await feeder.set_strategy("DWA_ONLY")
    return feeder


async def test_dwa_drives_along_a_clear_path_within_the_robots_limits(
    fast: Feeder, shipped_controller: None
) -> None:
    path = await publish_path(fast, [0.0, 3.0], [0.0, 0.0])
    row = (await dwa_rows(fast))[0]
    assert row["kind"] == "robot" and row["priority"] == 30
    assert row["expires_stamp"] - row["stamp"] == pytest.approx(0.5)
    assert row["inputs"]["planned_path"] == path and "laser_scan" in row["inputs"]
    # from rest, the Burger's 2.5 m/s^2 over the 0.3 s window reaches its 0.22 m/s cap
    assert row["linear_mps"] == pytest.approx(0.22) and row["angular_rps"] == 0.0
    assert row["reason"].startswith("dwa: best of")


async def test_dwa_slows_for_a_wall_across_the_path_to_stop_short_of_its_margin(
    fast: Feeder, shipped_controller: None
) -> None:
    await publish_path(fast, [0.0, 3.0], [0.0, 0.0])
    # 0.4 m ahead: the body (0.105 m) and the margin (0.05 m) may come 0.245 m nearer, so
    # of the speeds sampled from 0 to 0.22 m/s (0.0275 apart) the fastest whose 1.2 s
    # trajectory stays short of that is 0.1925 m/s
    wall = (-60.0, 60.0, 0.4)
    rows = await dwa_rows(fast, wall)
    assert all(r["linear_mps"] * 1.2 <= 0.245 for r in rows)
    assert rows[0]["linear_mps"] == pytest.approx(0.1925)


async def test_dwa_stops_once_on_an_empty_path_then_stays_silent(
    fast: Feeder, shipped_controller: None
) -> None:
    await publish_path(fast, [0.0, 3.0], [0.0, 0.0])
    moving = (await dwa_rows(fast))[-1]
    assert moving["linear_mps"] > 0
    empty = await publish_path(fast, [], [])
    stop = await eventually(lambda: _citing(fast, empty), "a dwa stop citing the empty path")
    assert (stop["linear_mps"], stop["angular_rps"]) == (0.0, 0.0)
    for _ in range(5):
        await fast.odometry(0.0)
        await fast.scan()
        await asyncio.sleep(PERIOD_S)
    after = [r for r in await fast.recommendations("dwa") if r["id"] > stop["id"]]
    assert after == []


async def _citing(feeder: Feeder, path_id: int) -> asyncpg.Record | None:
    await feeder.odometry(0.0)
    await feeder.scan()
    await asyncio.sleep(PERIOD_S)
    rows = await feeder.recommendations("dwa")
    return next((r for r in rows if r["inputs"].get("planned_path") == path_id), None)

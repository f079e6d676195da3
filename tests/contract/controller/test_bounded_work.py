"""One robot's strategy asks dwa for the heaviest decisions its params allow; another robot's
safety_stop still stops it on every scan, and runs before dwa whenever both act in the same
activation. The shipped controller (in-process), Postgres and Zenoh, fed as a foreign client
would; assertions on command_recommendation rows and the engine's counts, never on speed."""

from __future__ import annotations

import asyncio
import math
from collections.abc import AsyncIterator
from typing import Any

import pytest

from common.config import EngineSettings, ServiceConfig, ZenohSettings
from common.contract import keys
from common.engine.engine import Engine
from common.service import ScenarioService
from pnav._testing import running_service
from pnav_local.dwa import Dwa
from tests.contract.controller.conftest import Feeder, eventually

# the hostile tester's row: each size within its documented range (docs/CONTROLLER.md)
DWA_STALL = {
    "dwa_steps": 50,
    "dwa_linear_samples": 50,
    "dwa_angular_samples": 100,
    "dwa_horizon_s": 10,
}
# r1's own lidar: a Jackal's 720 beams, every one a hit 1 to 9 m away
JACKAL_RANGES = [1.0 + (beam * 37 % 80) / 10 for beam in range(720)]
AHEAD = (-10.0, 10.0, 0.18)  # inside safety_stop's reach at 0.15 m/s for the Burger
ROUNDS = 10


@pytest.fixture
async def controller(db_url: str, zenoh_settings: ZenohSettings) -> AsyncIterator[ScenarioService]:
    from services.controller.service import ControllerService

    config = ServiceConfig(
        service="controller",
        database_url=db_url,
        zenoh=zenoh_settings,
        engine=EngineSettings(period_s=0.05),
        stats_period_s=30.0,
        instance="controller-under-test",
    )
    async with running_service(ControllerService, config, settle_s=0.5) as service:
        yield service


async def publish_path(feeder: Feeder, length: float) -> None:
    row_id = await feeder.conn.fetchval(
        "INSERT INTO planned_path (robot_id, stamp, target, target_x, target_y, xs, ys, "
        "length_m) VALUES ($1, $2, 'goal', $3, 0, $4, $5, $3) RETURNING id",
        feeder.robot,
        feeder.now(),
        length,
        [0.0, length],
        [0.0, 0.0],
    )
    feeder.notifier.notify(keys.PLANNED_PATH, feeder.robot, row_id)


async def jackal_scan(feeder: Feeder, notify: bool = True) -> int:
    row_id: int = await feeder.conn.fetchval(
        "INSERT INTO laser_scan (robot_id, stamp, angle_min, angle_increment, range_min, "
        "range_max, ranges) VALUES ($1, $2, $3, $4, 0.1, 10.0, $5) RETURNING id",
        feeder.robot,
        feeder.now(),
        -math.pi,
        2 * math.pi / 720,
        JACKAL_RANGES,
    )
    if notify:
        feeder.notifier.notify(keys.LASER_SCAN, feeder.robot, row_id)
    return row_id


async def rows(feeder: Feeder) -> list[Any]:
    return list(
        await feeder.conn.fetch(
            "SELECT id, xmin::text AS tx, robot_id, source, reason, linear_mps, inputs "
            "FROM command_recommendation ORDER BY id"
        )
    )


async def test_safety_stop_of_one_robot_never_waits_behind_anothers_dwa(
    feeder: Feeder, controller: ScenarioService
) -> None:
    r1 = feeder
    r2 = Feeder(feeder.conn, feeder.session, "r2")
    r2.started = r1.started  # one sim clock (r1's feeder publishes it)
    await r2.add_robot()
    # r1 is a Jackal: its speed and horizon reach every hit of the scan
    await r1.conn.execute(
        "UPDATE robot SET max_linear_mps = 2.0, max_angular_rps = 4.0, footprint_radius_m = "
        "0.22, max_linear_accel_mps2 = 10.0, max_angular_accel_rps2 = 20.0 WHERE robot_id = 'r1'"
    )
    r1.notifier.notify(keys.ROBOT, "r1", None)
    await r1.add_strategy("DWA_STALL", ["dwa"], DWA_STALL)
    await r1.add_strategy("STOP_ONLY", ["safety_stop"], {})

    async def runs(feeder: Feeder, source: str) -> bool:
        if feeder is r1:
            await r1.odometry(1.0)
            await jackal_scan(r1)
        else:
            await r2.odometry(0.15)
            await r2.scan(AHEAD)
        await asyncio.sleep(0.2)
        return any(r["robot_id"] == feeder.robot and r["source"] == source for r in await rows(r1))

    # r2's safety_stop first, then r1's dwa: the engine's queue has dwa ahead of it (the
    # meta rule queues a new scenario before the clones of those it runs already)
    await r2.set_strategy("STOP_ONLY")
    await eventually(lambda: runs(r2, "safety_stop"), "safety_stop for r2", 30.0)
    await r1.set_strategy("DWA_STALL")
    await publish_path(r1, 3.0)
    await eventually(lambda: runs(r1, "dwa"), "dwa for r1", 30.0)

    stop_scans = []
    for _ in range(ROUNDS):
        # r1's scan, then r2's, each notified: r2's comes while r1's dwa decides
        await r1.odometry(1.0)
        await jackal_scan(r1)
        await r2.odometry(0.15)
        stop_scans.append(await r2.scan(AHEAD))
        await asyncio.sleep(0.2)
    for _ in range(ROUNDS):
        # both robots' scans, then one notification for every robot: an activation that
        # runs both robots' scenarios (unless the engine's fallback F came between)
        await r1.odometry(1.0)
        await r2.odometry(0.15)
        await jackal_scan(r1, notify=False)
        stop_scans.append(await r2.scan(AHEAD, notify=False))
        r1.notifier.notify(keys.LASER_SCAN, None, None)
        await asyncio.sleep(0.2)

    async def every_scan_stopped() -> bool:
        stopped = {
            r["inputs"]["laser_scan"]
            for r in await rows(r1)
            if r["robot_id"] == "r2" and r["source"] == "safety_stop" and r["linear_mps"] == 0
        }
        return set(stop_scans) <= stopped

    # every one of r2's scans was stopped on (a scan not acted on within 0.5 s of sim time
    # is stale: a safety_stop waiting behind a stalled dwa would have missed them)
    await eventually(every_scan_stopped, "a stop on every scan of r2", 30.0)

    written = await rows(r1)
    dwa = [r for r in written if r["source"] == "dwa"]
    assert dwa and all("params scaled to 14 x 26 samples x 15 steps" in r["reason"] for r in dwa)
    # in each INSERT (one per activation) that holds both, safety_stop's row comes first
    together = 0
    for tx in {r["tx"] for r in dwa}:
        batch = [r for r in written if r["tx"] == tx]
        stops = [r["id"] for r in batch if r["source"] == "safety_stop"]
        if stops:
            together += 1
            assert max(stops) < min(r["id"] for r in batch if r["source"] == "dwa")
    assert together >= 1, "no activation decided both robots' scans"
    engine: Engine = controller.engine
    assert engine.counters.safety_run >= 2 * ROUNDS
    assert engine.stats_for(Dwa).executed >= 2 * ROUNDS

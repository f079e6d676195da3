"""The controller while people hold strategy locked and goal's rows (CONTRACT.md, *Roles*: "Locks"):
safety_stop recommends on every scan; the strategies held serve until a read gets through.
"""

from __future__ import annotations

import asyncio
import time

from common.config import EngineSettings, ServiceConfig, ZenohSettings
from common.contract.grants import role_name
from common.contract.roles import role_url
from pnav._testing import as_service_role, running_service
from pnav.bench.faults import tablelock
from services.controller.service import ControllerService
from services.controller.store import ControllerStore
from tests.contract.controller.conftest import Feeder, eventually
from tests.contract.controller.test_controller import AHEAD, PERIOD_S

HOLD_S = 5.0


async def test_the_controller_stops_on_every_scan_while_people_lock_strategy_and_goal(
    db_url: str, zenoh_settings: ZenohSettings, feeder: Feeder
) -> None:
    config = ServiceConfig(
        service="controller",
        database_url=await as_service_role(db_url, "controller"),
        zenoh=zenoh_settings,
        engine=EngineSettings(period_s=0.05),
        stats_period_s=30.0,
        instance="controller-under-test",
    )
    async with running_service(ControllerService, config, settle_s=0.5) as controller:
        store: ControllerStore = controller.store  # type: ignore[attr-defined]
        await feeder.add_strategy("STOP_ONLY", ["safety_stop"], {})
        await feeder.set_strategy("STOP_ONLY")

        async def stops() -> bool:
            await feeder.odometry(0.2)
            await feeder.scan(AHEAD)
            await asyncio.sleep(PERIOD_S)
            return bool(await feeder.recommendations("safety_stop"))

        await eventually(stops, "a first safety stop", 30.0)
        scans: list[int] = []
        async with tablelock.held(role_url(db_url, role_name("user"), None)):
            end = time.monotonic() + HOLD_S
            while time.monotonic() < end:
                await feeder.odometry(0.2)
                scans.append(await feeder.scan(AHEAD))
                await asyncio.sleep(PERIOD_S)
            refusals = store.meta_lock_refusals
        assert refusals >= 1, "the controller never read the locked strategies"

        async def every_scan_stopped() -> bool:
            stopped = {
                r["inputs"]["laser_scan"]
                for r in await feeder.recommendations("safety_stop")
                if r["linear_mps"] == 0
            }
            return set(scans) <= stopped

        # a scan not acted on within 0.5 s of sim time is stale: a safety_stop waiting
        # behind the lock for long would have missed some
        await eventually(every_scan_stopped, "a stop on every scan under the lock", 30.0)

        async def read_again() -> bool:
            return not store.meta_locked

        await eventually(read_again, "the strategies read again", 15.0)

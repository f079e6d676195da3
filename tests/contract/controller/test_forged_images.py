"""Forged laser_scan and planned_path images (CONTRACT.md "Row images", "Forged images"):
the controller holds each image to its table's rules before it stands in for a read, so an
image no row could be (a NaN stamp, another robot's row on r1's key, an id no sequence
gives, paths of mismatched lengths) is dropped, counted, and the table read instead; the
controller goes on recommending from the rows the bridge wrote.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import AsyncIterator
from typing import Any

import pytest

from common.config import EngineSettings, ServiceConfig, ZenohSettings
from common.contract import keys
from common.runtime import Runtime
from pnav._testing import eventually, publish_clock, running_service
from services.controller.service import ControllerService
from services.controller.store import ControllerStore
from tests.contract.controller.conftest import ROBOT, SIM_START
from tests.contract.controller.test_images import scan_image, write_scan

FORGED_ID = 10**9


@pytest.fixture
async def client(db_url: str, zenoh_settings: ZenohSettings) -> AsyncIterator[Runtime]:
    config = ServiceConfig(service="test-client", database_url=db_url, zenoh=zenoh_settings)
    runtime = await Runtime.open(config)
    try:
        await runtime.database.write(
            keys.ROBOT, ROBOT, "INSERT INTO robot (robot_id, world) VALUES ($1, 'test')", ROBOT
        )
        await runtime.database.write(
            keys.ACTIVE_STRATEGY,
            ROBOT,
            "INSERT INTO active_strategy (robot_id, strategy_code, source, stamp) "
            "VALUES ($1, 'GOTO_AVOID', 'user', 0)",
            ROBOT,
        )
        yield runtime
    finally:
        await runtime.close()


def clear_scan(row_id: int, at: float, **changes: Any) -> dict[str, Any]:
    """A scan that sees nothing: what a forger would send to hide an obstacle."""
    image = scan_image(at)
    image["ranges"] = [math.inf] * len(image["ranges"])
    return {**image, "id": row_id, **changes}


async def test_forged_scan_and_path_images_are_dropped_and_counted(
    db_url: str, zenoh_settings: ZenohSettings, client: Runtime
) -> None:
    config = ServiceConfig(
        service="controller",
        database_url=db_url,
        zenoh=zenoh_settings,
        engine=EngineSettings(period_s=0.05),
        stats_period_s=30.0,
        instance="controller-forged",
    )
    db = client.database
    async with running_service(ControllerService, config, settle_s=0.5) as service:
        store = service.store  # type: ignore[attr-defined]
        assert isinstance(store, ControllerStore)
        now = SIM_START + 0.05
        publish_clock(client.zenoh, now)
        scans = [
            clear_scan(FORGED_ID, now, stamp=math.nan),
            clear_scan(FORGED_ID + 1, now, robot_id="r2"),
            clear_scan(0, now),  # no sequence gives 0
            clear_scan(FORGED_ID + 2, now, range_max=math.inf),
        ]
        for image in scans:
            db.notifier.notify(keys.LASER_SCAN, ROBOT, image["id"], image)
        path = {
            "id": FORGED_ID,
            "robot_id": ROBOT,
            "stamp": now,
            "goal_id": None,
            "target": "goal",
            "target_x": 1.0,
            "target_y": 1.0,
            "xs": [0.0, 1.0],
            "ys": [0.0],
            "length_m": 1.0,
        }
        db.notifier.notify(keys.PLANNED_PATH, ROBOT, FORGED_ID, path)
        expected = {keys.LASER_SCAN: len(scans), keys.PLANNED_PATH: 1}
        await eventually(
            lambda: store.images_refused == expected, within=30, what="every forgery refused"
        )
        assert service.images_refused() == expected
        # the rows the bridge writes are still acted on, from their own images
        scan_ids = []
        for _ in range(6):
            now += 0.05
            publish_clock(client.zenoh, now)
            scan_ids.append(await write_scan(db, scan_image(now)))
            await asyncio.sleep(0.05)

        async def recommended() -> list[Any]:
            rows = await db.pool.fetch(
                "SELECT inputs FROM command_recommendation WHERE source = 'avoid_left'"
            )
            return list(rows)

        rows = await eventually(recommended, within=30, what="avoid_left to recommend")
        assert all(r["inputs"]["laser_scan"] in scan_ids for r in rows)
        assert store.images_refused == expected  # the real images kept the rules

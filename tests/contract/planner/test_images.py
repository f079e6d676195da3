"""The planner with row images (CONTRACT.md "Row images"), against Postgres and Zenoh: the
robot's odometry written as the bridge writes it, each notification with its row.

With images the planner drives toward its goal without reading the odometry table (the
image of the newest row stands in for the query); with PNAV_NOTIFY_IMAGES=off for the
planner and for the test's writes, it reads the table and recommends the same.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator

import pytest

from common.config import EngineSettings, ServiceConfig, ZenohSettings
from common.contract import keys
from pnav._testing import running_service
from services.planner.service import PlannerService
from services.planner.store import PlannerStore
from tests.contract.planner.conftest import ROBOT, World

ODOMETRY_SQL = (
    "INSERT INTO odometry (robot_id, stamp, x, y, yaw, linear_mps, angular_rps) "
    "VALUES ($1, $2, $3, $4, $5, $6, $7) RETURNING id"
)


async def odometry_with_images(world: World) -> None:
    """The robot's pose at 10 Hz, each row's notification with its image (unless the
    notifier's images are off)."""
    while True:
        x, y, yaw = world.pose
        image = {"robot_id": ROBOT, "stamp": world.now(), "x": x, "y": y, "yaw": yaw}
        image |= {"linear_mps": 0.0, "angular_rps": 0.0}
        await world.db.write(keys.ODOMETRY, ROBOT, ODOMETRY_SQL, *image.values(), image=image)
        await asyncio.sleep(0.1)


@pytest.fixture(params=["images", "images off"])
def images(request: pytest.FixtureRequest) -> bool:
    return bool(request.param == "images")


@pytest.fixture
async def feeding(world: World, images: bool) -> AsyncIterator[None]:
    world.streaming = False  # the fixture's own odometry has no image: this one instead
    world.db.notifier.images = images
    task = asyncio.create_task(odometry_with_images(world))
    try:
        yield
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


async def test_the_planner_drives_on_odometry_images_without_reading_them(
    world: World, feeding: None, images: bool, db_url: str, zenoh_settings: ZenohSettings
) -> None:
    config = ServiceConfig(
        service="planner",
        database_url=db_url,
        zenoh=zenoh_settings,
        engine=EngineSettings(period_s=0.05),
        stats_period_s=5.0,
        instance="planner-images",
        notify_images=images,
    )
    async with running_service(PlannerService, config, settle_s=0.5) as service:
        store = service.store  # type: ignore[attr-defined]
        assert isinstance(store, PlannerStore)
        await world.strategy("GOTO_AVOID")
        goal = await world.goal(2.0, 0.0)
        first = await world.next_recommendation(lambda r: r["inputs"].get("goal") == goal)
        reads = store.odometry_reads
        later = await world.next_recommendation(
            lambda r: r["inputs"].get("goal") == goal, after=first["id"] + 5
        )
        assert later["source"] == "turn_then_move" and later["linear_mps"] > 0
        odometry = await world.db.pool.fetchrow(
            "SELECT id, stamp FROM odometry WHERE id = $1", later["inputs"]["odometry"]
        )
        assert odometry is not None and later["stamp"] == odometry["stamp"]
        if images:
            assert store.odometry_reads == reads  # every odometry from its image
        else:
            assert store.odometry_reads > reads

"""Row images against Postgres and Zenoh (CONTRACT.md "Row images").

- The records built from a row's image are the records the queries read back from the table.
- The shipped controller, fed scans and odometry whose notifications carry their images (as
  the bridge sends them), recommends without reading the scan table; the odometry is one
  query per scan, unless the service hears odometry too (``listens``), then none.
- With images off (PNAV_NOTIFY_IMAGES=off) for the controller and for the test's own writes,
  it works as before, reading the table for every scan.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import AsyncIterator
from typing import Any

import pytest

from common.config import EngineSettings, ServiceConfig, ZenohSettings
from common.contract import keys, records
from common.db import Database
from common.runtime import Runtime
from pnav._testing import publish_clock, running_service
from services.controller.service import ControllerService
from services.controller.store import ODOMETRY_LISTENS, ControllerStore
from tests.contract.controller.conftest import BEAMS, ROBOT, SIM_START, eventually

RIGHT_DEG = range(-40, -19)  # an obstacle front-right at 0.30 m: avoid_left turns away


def scan_image(stamp: float) -> dict[str, Any]:
    ranges = [math.inf] * BEAMS
    for deg in RIGHT_DEG:
        ranges[deg % BEAMS] = 0.30
    return {
        "robot_id": ROBOT,
        "stamp": stamp,
        "seq": 0,
        "angle_min": 0.0,
        "angle_increment": 2 * math.pi / BEAMS,
        "range_min": 0.12,
        "range_max": 3.5,
        "ranges": ranges,
    }


def odometry_image(stamp: float) -> dict[str, Any]:
    return {"robot_id": ROBOT, "stamp": stamp, "seq": 0, "x": 1.0, "y": 2.0, "yaw": 0.5}


SCAN_SQL = (
    "INSERT INTO laser_scan (robot_id, stamp, seq, angle_min, angle_increment, range_min, "
    "range_max, ranges) VALUES ($1, $2, $3, $4, $5, $6, $7, $8) RETURNING id"
)
ODOMETRY_SQL = (
    "INSERT INTO odometry (robot_id, stamp, seq, x, y, yaw, linear_mps, angular_rps) "
    "VALUES ($1, $2, $3, $4, $5, $6, $7, $8) RETURNING id"
)


async def write_scan(db: Database, image: dict[str, Any]) -> int:
    """A laser_scan row and its notification with the image, as the bridge writes them."""
    return int(await db.write(keys.LASER_SCAN, ROBOT, SCAN_SQL, *image.values(), image=image))


async def write_odometry(db: Database, image: dict[str, Any]) -> int:
    return int(await db.write(keys.ODOMETRY, ROBOT, ODOMETRY_SQL, *image.values(), image=image))


@pytest.fixture
async def client(db_url: str, zenoh_settings: ZenohSettings) -> AsyncIterator[Runtime]:
    """The test's own writer (its notifications carry images unless a test turns them off)."""
    config = ServiceConfig(service="test-client", database_url=db_url, zenoh=zenoh_settings)
    runtime = await Runtime.open(config)
    try:
        await runtime.database.write(
            keys.ROBOT, ROBOT, "INSERT INTO robot (robot_id, world) VALUES ($1, 'test')", ROBOT
        )
        yield runtime
    finally:
        await runtime.close()


async def test_the_records_of_images_are_the_records_read_from_the_table(
    client: Runtime,
) -> None:
    db = client.database
    scan = scan_image(12.5)
    scan_id = await write_scan(db, scan)
    odometry = odometry_image(12.5) | {"linear_mps": 0.2, "angular_rps": -0.1}
    odometry_id = await write_odometry(db, odometry)
    read_scan = await records.newest_scan(db.pool, ROBOT)
    from_image = records.laser_scan_of({**scan, "id": scan_id})
    assert read_scan is not None
    geometry = ("id", "robot_id", "stamp", "angle_min", "angle_increment", "range_min")
    for field in (*geometry, "range_max"):
        assert getattr(from_image, field) == getattr(read_scan, field), field
    assert from_image.ranges.dtype == read_scan.ranges.dtype
    assert from_image.ranges.tolist() == read_scan.ranges.tolist()
    packed = records.laser_scan_of(
        {**scan, "id": scan_id, "ranges": read_scan.ranges.astype("<f4").tobytes()}
    )
    assert packed.ranges.tolist() == read_scan.ranges.tolist()
    read_odometry = await records.newest_odometry(db.pool, ROBOT)
    assert records.odometry_of({**odometry, "id": odometry_id}) == read_odometry


class HearingController(ControllerService):
    """The controller hearing odometry too (off by default: see ControllerStore.listens)."""

    listens = ODOMETRY_LISTENS


@pytest.fixture(params=["images", "images off", "images, odometry heard"])
def variant(request: pytest.FixtureRequest) -> str:
    return str(request.param)


async def test_the_controller_recommends_from_images_without_reading_the_table(
    db_url: str, zenoh_settings: ZenohSettings, client: Runtime, variant: str
) -> None:
    """With images, the scan and odometry come with their notifications: no query (the
    period fallback aside: nothing is lost here, and the scans come faster than it). With
    PNAV_NOTIFY_IMAGES=off on both sides, the controller reads the table for every scan and
    recommends the same. Hearing odometry (not by default), the odometry query goes too."""
    images, hearing = variant != "images off", variant == "images, odometry heard"
    client.database.notifier.images = images  # the test's writes, as PNAV_NOTIFY_IMAGES says
    config = ServiceConfig(
        service="controller",
        database_url=db_url,
        zenoh=zenoh_settings,
        engine=EngineSettings(period_s=0.05),
        stats_period_s=30.0,
        instance="controller-images",
        notify_images=images,
    )
    db = client.database
    await db.write(
        keys.ACTIVE_STRATEGY,
        ROBOT,
        "INSERT INTO active_strategy (robot_id, strategy_code, source, stamp) "
        "VALUES ($1, 'GOTO_AVOID', 'user', 0)",
        ROBOT,
    )
    service_cls = HearingController if hearing else ControllerService
    async with running_service(service_cls, config, settle_s=0.5) as service:
        store = service.store  # type: ignore[attr-defined]
        assert isinstance(store, ControllerStore)
        now = SIM_START
        scan_ids = []
        reads: list[tuple[int, int]] = []  # (scan reads, odometry reads) after each scan
        for _ in range(12):
            now += 0.05
            publish_clock(client.zenoh, now)
            odometry = odometry_image(now) | {"linear_mps": 0.0, "angular_rps": 0.0}
            await write_odometry(db, odometry)
            scan_ids.append(await write_scan(db, scan_image(now)))
            await asyncio.sleep(0.05)
            reads.append((store.scans.reads, store.odometry_reads))

        async def recommended() -> list[Any]:
            rows = await db.pool.fetch(
                "SELECT * FROM command_recommendation WHERE source = 'avoid_left' ORDER BY id"
            )
            return list(rows)

        rows = await eventually(recommended, "avoid_left to recommend")
        assert rows[0]["angular_rps"] > 0
        assert rows[-1]["inputs"]["laser_scan"] in scan_ids
        # from the third scan on (the first looks may come before the strategy is read)
        scan_reads = reads[-1][0] - reads[1][0]
        odometry_reads = reads[-1][1] - reads[1][1]
        if hearing:
            assert store.images_used >= 10
            assert (scan_reads, odometry_reads) == (0, 0)  # no query: the images stood in
            assert store.odometry_images_used >= 5
        elif images:
            assert store.images_used >= 10
            assert scan_reads == 0  # the scans' images stood in for the scan query
            assert odometry_reads >= 5 and store.odometry_images_used == 0  # odometry: read
        else:
            assert store.images_used == 0 and store.odometry_images_used == 0
            assert scan_reads >= 5  # every scan it looked at was read from the table

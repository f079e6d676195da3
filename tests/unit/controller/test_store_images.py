"""The controller's store with row images (CONTRACT.md "Row images"): a scan's image stands
in for the query, with the newest odometry image; no image, a ``seq`` gap or an image older
than ``recheck_s`` means reading the table, as without images."""

from __future__ import annotations

from common.bus import Notification
from common.contract import keys
from services.controller.store import RECHECK_S
from tests.unit.controller.rig import Rig
from tests.unit.controller.test_store import CountingSource


def rig() -> Rig:
    return Rig(source=CountingSource, images=True)


def odometry_reads(r: Rig) -> int:
    assert isinstance(r.source, CountingSource)
    return r.source.odometry_reads


async def test_a_scan_and_odometry_from_images_need_no_query() -> None:
    r = rig()
    store = r.store
    odom = r.odometry(0.2)
    first = r.new_scan()
    scan = await store.newest_scan("r1")
    assert scan is not None and scan.id == first
    assert store.scans.reads == 0  # the image stood in for the query
    odometry = await store.odometry_at(scan)
    assert odometry is not None and (odometry.id, odometry.linear_mps) == (odom, 0.2)
    assert odometry_reads(r) == 0
    assert (store.images_used, store.odometry_images_used) == (1, 1)
    # the same scan asked again (another scenario): the same odometry, even if newer came
    r.odometry(0.3)
    assert await store.odometry_at(scan) == odometry
    second = r.new_scan()
    newer = await store.newest_scan("r1")
    assert newer is not None and newer.id == second
    newest = await store.odometry_at(newer)
    assert newest is not None and newest.linear_mps == 0.3
    assert (store.scans.reads, odometry_reads(r)) == (0, 0)


async def test_the_image_gives_the_record_the_query_gives() -> None:
    r = rig()
    r.odometry(0.2)
    r.new_scan()
    from_image = await r.store.newest_scan("r1")
    read, odometry = await r.source.newest_scan_and_odometry("r1")
    assert from_image is not None and read is not None
    assert (from_image.id, from_image.stamp, from_image.angle_increment) == (
        read.id,
        read.stamp,
        read.angle_increment,
    )
    assert from_image.ranges.dtype == read.ranges.dtype
    assert from_image.ranges.tolist() == read.ranges.tolist()
    assert await r.store.odometry_at(from_image) == odometry


async def test_no_image_or_a_gap_reads_the_table() -> None:
    r = rig()
    store = r.store
    r.new_scan()
    await store.newest_scan("r1")
    assert store.scans.reads == 0
    r.images = False
    second = r.new_scan()  # a bare hint: read
    assert (await scan_id(r)) == second and store.scans.reads == 1
    r.images = True
    r.seqs[(keys.LASER_SCAN, "r1")] += 1  # a notification lost on the way
    third = r.new_scan()
    assert (await scan_id(r)) == third and store.scans.reads == 2
    assert store.notifications_lost == 1  # what the "engine stopped" line reports
    fourth = r.new_scan()  # numbered on from the last: an image again
    assert (await scan_id(r)) == fourth and store.scans.reads == 2


async def test_no_odometry_image_or_an_old_one_reads_the_odometry() -> None:
    r = rig()
    store = r.store
    r.new_scan()  # no odometry heard yet
    scan = await store.newest_scan("r1")
    assert scan is not None
    assert await store.odometry_at(scan) is None  # the table has none either
    assert odometry_reads(r) == 1
    r.odometry(0.2)
    r.wall += RECHECK_S  # heard, but longer ago than the store's period
    r.new_scan()
    scan = await store.newest_scan("r1")
    assert scan is not None
    odometry = await store.odometry_at(scan)
    assert odometry is not None and odometry.linear_mps == 0.2
    assert odometry_reads(r) == 2
    store.note(Notification(keys.ODOMETRY, "r1", None))  # a bare odometry hint
    r.new_scan()
    scan = await store.newest_scan("r1")
    assert scan is not None
    await store.odometry_at(scan)
    assert odometry_reads(r) == 3


async def test_nothing_heard_for_the_period_reads_the_table() -> None:
    r = rig()
    store = r.store
    first = r.new_scan()
    await store.newest_scan("r1")
    r.wall += RECHECK_S  # no notification since: maybe one was lost
    assert (await scan_id(r)) == first and store.scans.reads == 1


async def scan_id(r: Rig) -> int | None:
    scan = await r.store.newest_scan("r1")
    return scan.id if scan is not None else None

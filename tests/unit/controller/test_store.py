"""The controller's store on the in-memory contract: it reads again only when a notification
announced something newer (or named nothing, or ``recheck_s`` passed on its clock), hands
out the odometry read with a scan, and remembers what it recommended on until the robot
changes hands."""

from __future__ import annotations

from common.bus import Notification
from common.contract import keys
from common.contract.recommendations import Recommendation
from common.contract.records import Odometry, Strategy
from pnav.monolith.contract import MemoryContract
from pnav.monolith.memory_controller import MemoryControllerSource
from services.controller.store import RECHECK_S
from tests.unit.controller.rig import Rig

DIRECT = Strategy("GOTO_DIRECT", None, ("safety_stop",), {})


class CountingSource(MemoryControllerSource):
    """The in-memory contract, counting the lone odometry reads."""

    def __init__(self, contract: MemoryContract) -> None:
        super().__init__(contract)
        self.odometry_reads = 0

    async def newest_odometry(self, robot_id: str) -> Odometry | None:
        self.odometry_reads += 1
        return await super().newest_odometry(robot_id)


def recommendation(scan_id: int, source: str = "safety_stop") -> Recommendation:
    inputs = {"laser_scan": scan_id, "scan_stamp": 10.0}
    return Recommendation.velocity(
        "r1",
        source=source,
        priority=100,
        linear=0.0,
        angular=0.5,
        stamp=10.0,
        ttl_s=0.5,
        reason="test",
        inputs=inputs,
    )


async def scan_id(rig: Rig) -> int | None:
    scan = await rig.store.newest_scan("r1")
    return scan.id if scan is not None else None


async def test_a_scan_is_read_again_only_when_a_newer_one_is_announced() -> None:
    rig = Rig()
    store, scans = rig.store, rig.store.scans
    first = rig.new_scan()
    assert [await scan_id(rig) for _ in range(3)] == [first] * 3
    assert scans.reads == 1
    store.note(Notification(keys.LASER_SCAN, "r1", first))  # a late hint of the same row
    await store.newest_scan("r1")
    assert scans.reads == 1
    second = rig.new_scan()  # announced with its id: read at the next ask
    assert await scan_id(rig) == second
    assert scans.reads == 2


async def test_an_id_less_hint_or_the_recheck_period_makes_it_read_again() -> None:
    rig = Rig()
    store, scans = rig.store, rig.store.scans
    await store.newest_scan("r1")
    assert scans.reads == 1
    store.note(Notification(keys.LASER_SCAN, "r1", None))  # "something changed"
    await store.newest_scan("r1")
    assert scans.reads == 2
    rig.wall += RECHECK_S  # a hint may have been lost: read again after recheck_s
    await store.newest_scan("r1")
    await store.newest_scan("r1")
    assert scans.reads == 3


async def test_robots_and_strategies_are_read_again_after_either_changes() -> None:
    rig = Rig()
    store, tables = rig.store, rig.store.tables
    assert await store.active_strategies() == {}
    await store.robots()
    assert tables.reads == 1  # read together
    rig.new_scan()  # another table: no reason to read them again
    await store.robots()
    assert tables.reads == 1
    rig.set_strategy("r1", DIRECT)  # strategy, then active_strategy
    assert (await store.active_strategies())["r1"].strategy == DIRECT
    assert tables.reads == 2


async def test_the_odometry_of_a_scan_is_the_one_read_with_it() -> None:
    rig = Rig(source=CountingSource)
    source = rig.source
    assert isinstance(source, CountingSource)
    odometry = rig.odometry(0.15)
    rig.new_scan()
    scan = await rig.store.newest_scan("r1")
    assert scan is not None
    rig.odometry(0.0)  # newer than the scan's: not what a decision about the scan wants
    at_scan = await rig.store.odometry_at(scan)
    assert at_scan is not None and (at_scan.id, at_scan.linear_mps) == (odometry, 0.15)
    assert source.odometry_reads == 0  # no round trip of its own


async def test_a_scan_the_store_no_longer_holds_has_its_odometry_read_once() -> None:
    rig = Rig(source=CountingSource)
    source = rig.source
    assert isinstance(source, CountingSource)
    rig.odometry(0.15)
    rig.new_scan()
    old = await rig.store.newest_scan("r1")
    assert old is not None
    rig.new_scan()
    await rig.store.newest_scan("r1")  # the store moved on to the newer scan
    newest = rig.odometry(0.1)
    ids = []
    for _ in range(3):
        odometry = await rig.store.odometry_at(old)
        ids.append(odometry.id if odometry is not None else None)
    assert ids == [newest] * 3
    assert source.odometry_reads == 1  # shared by every scenario that asks about that scan


async def test_what_was_recommended_on_is_kept_until_the_robot_changes_hands() -> None:
    rig = Rig()
    store = rig.store
    assert store.last_recommended_scan("r1", "safety_stop") is None
    await store.recommend(recommendation(4))
    assert rig.recommendations() == []  # held until the activation ends
    assert store.last_recommended_scan("r1", "safety_stop") is None
    await store.defer_recommendations()()  # the engine's activation-end hook
    row = rig.recommendations()[-1]
    assert (row["kind"], row["expires_stamp"]) == ("robot", 10.5)
    assert store.last_recommended_scan("r1", "safety_stop") == 4
    assert store.last_recommended_scan("r1", "avoid_left") is None  # per scenario
    await store.newest_scan("r1")
    store.forget({"r1"})
    assert store.last_recommended_scan("r1", "safety_stop") is None
    assert store.scans.peek("r1") is None

"""Batching across robots in the controller's store (docs/ARCHITECTURE.md), step by step on
the in-memory contract: one odometry query serves every robot served whose scan came as an
image, and an activation's recommendations go in one write at its end."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

from common.contract.recommendations import Recommendation
from common.contract.records import Odometry, Strategy
from pnav.monolith.contract import MemoryContract
from pnav.monolith.memory_controller import MemoryControllerSource
from services.controller.safety_stop import SafetyStop
from tests.unit.controller.rig import Rig
from tests.unit.controller.scans import BURGER

STOP = Strategy("STOP", None, ("safety_stop",), {})
AHEAD = (-5.0, 5.0, 0.15)  # straight ahead, within its stopping distance: safety_stop fires


class CountingSource(MemoryControllerSource):
    """The in-memory contract, recording each odometry query and each write call."""

    def __init__(self, contract: MemoryContract) -> None:
        super().__init__(contract)
        self.lone_reads: list[str] = []
        self.batch_reads: list[list[str]] = []
        self.writes: list[list[str]] = []  # per call: the robots of its rows

    async def newest_odometry(self, robot_id: str) -> Odometry | None:
        self.lone_reads.append(robot_id)
        return await super().newest_odometry(robot_id)

    async def newest_odometries(self, robot_ids: Sequence[str]) -> dict[str, Odometry | None]:
        self.batch_reads.append(sorted(robot_ids))
        lone = MemoryControllerSource.newest_odometry
        return {robot_id: await lone(self, robot_id) for robot_id in robot_ids}

    async def recommend(self, recommendation: Recommendation) -> int:
        self.writes.append([recommendation.robot_id])
        return await super().recommend(recommendation)

    async def recommend_many(self, recommendations: Sequence[Recommendation]) -> list[int | None]:
        self.writes.append([r.robot_id for r in recommendations])
        write = MemoryControllerSource.recommend
        return [await write(self, r) for r in recommendations]


def three_robots() -> tuple[Rig, CountingSource]:
    rig = Rig(scenarios={"safety_stop": SafetyStop}, source=CountingSource, images=True)
    for robot_id in ("r2", "r3"):
        rig.add_robot(replace(BURGER, robot_id=robot_id))
    assert isinstance(rig.source, CountingSource)
    return rig, rig.source


async def test_one_odometry_query_serves_every_robot_served_with_a_scan_image() -> None:
    rig, source = three_robots()
    store = rig.store
    rig.owned = {"r1", "r2"}  # r3 is another replica's
    odometry = {r: rig.odometry(0.1, robot_id=r, heard=False) for r in ("r1", "r2", "r3")}
    scans = {}
    for robot_id in ("r1", "r2", "r3"):
        rig.new_scan(robot_id=robot_id)  # heard with its image
        scans[robot_id] = await store.newest_scan(robot_id)
    assert store.scans.reads == 0  # every scan from its image
    r1 = await store.odometry_at(scans["r1"])
    assert r1 is not None and r1.id == odometry["r1"]
    assert (source.batch_reads, source.lone_reads) == ([["r1", "r2"]], [])  # r3 not served
    r2 = await store.odometry_at(scans["r2"])  # r2's rule, later in the activation
    assert r2 is not None and r2.id == odometry["r2"]
    assert (source.batch_reads, source.lone_reads) == ([["r1", "r2"]], [])  # no query
    # a robot not served still gets its odometry when asked: a query of its own
    r3 = await store.odometry_at(scans["r3"])
    assert r3 is not None and r3.id == odometry["r3"]
    assert (source.batch_reads, source.lone_reads) == ([["r1", "r2"]], ["r3"])
    assert store.odometry_reads == 2
    # r1's next scan: r2's held scan has its odometry already, so r1 is asked alone
    rig.new_scan(robot_id="r1")
    newer = await store.newest_scan("r1")
    assert newer is not None and newer.id != scans["r1"].id
    await store.odometry_at(newer)
    assert source.lone_reads == ["r3", "r1"]


async def test_an_activations_recommendations_go_in_one_write_at_its_end() -> None:
    rig, source = three_robots()
    for robot_id in ("r1", "r2", "r3"):
        rig.set_strategy(robot_id, STOP)
        rig.odometry(0.2, robot_id=robot_id, heard=False)  # driving ahead
    assert await rig.tick() == []  # the meta starts each robot's safety_stop
    assert sorted(rig.running()) == [(r, "safety_stop") for r in ("r1", "r2", "r3")]
    for robot_id in ("r1", "r2", "r3"):
        rig.new_scan(AHEAD, robot_id=robot_id)
    assert await rig.tick() == ["safety_stop"] * 3  # each robot stops, on its scan
    assert source.writes == [["r1", "r2", "r3"]]  # in one write, at the activation's end
    assert source.batch_reads == [["r1", "r2", "r3"]]  # and their odometry in one query
    assert {row["robot_id"] for row in rig.recommendations()} == {"r1", "r2", "r3"}
    for robot_id in ("r1", "r2", "r3"):  # each knows it recommended on that scan
        scan = await rig.store.newest_scan(robot_id)
        assert scan is not None
        assert rig.store.last_recommended_scan(robot_id, "safety_stop") == scan.id
    assert await rig.tick() == []  # no new scan: nothing held, nothing written
    assert source.writes == [["r1", "r2", "r3"]]


async def test_a_robot_with_a_fresh_odometry_image_is_left_out_of_the_batched_query() -> None:
    rig, source = three_robots()
    store = rig.store
    rig.odometry(0.1, robot_id="r1", heard=False)
    heard = rig.odometry(0.2, robot_id="r2")  # its image reaches the store
    rig.odometry(0.3, robot_id="r3", heard=False)
    scans = {}
    for robot_id in ("r1", "r2", "r3"):
        rig.new_scan(robot_id=robot_id)
        scans[robot_id] = await store.newest_scan(robot_id)
    # r1 has no odometry image: one query for it and r3, not for r2, whose image stands in
    r1 = await store.odometry_at(scans["r1"])
    assert r1 is not None and r1.linear_mps == 0.1
    assert (source.batch_reads, source.lone_reads) == ([["r1", "r3"]], [])
    r2 = await store.odometry_at(scans["r2"])
    assert r2 is not None and r2.id == heard  # from its image: no query
    r3 = await store.odometry_at(scans["r3"])
    assert r3 is not None and r3.linear_mps == 0.3  # read with r1's: no query
    assert (source.batch_reads, source.lone_reads) == ([["r1", "r3"]], [])
    assert store.odometry_images_used == 1

"""ScenarioService.owns: a tiny service's rules act only for the robots its replica owns."""

from __future__ import annotations

import asyncio
from dataclasses import replace

import asyncpg

from common.config import EngineSettings, LeaseSettings, ServiceConfig, ZenohSettings
from common.contract import keys
from common.engine import Rule
from common.lease import ownership
from common.runtime import Runtime
from common.service import ScenarioService
from pnav._testing import eventually, running_service

SERVICE = "counter"


class CountOwned(Rule):
    """A meta rule that counts, per robot, the activations in which its replica owned it."""

    scenario = "count_owned"
    meta = True
    watches = (keys.ROBOT,)

    def __init__(self, service: CounterService) -> None:
        self.service = service

    async def data_acquisition(self) -> None:
        async with self.service.runtime.database.pool.acquire() as conn:
            self.robots = [r["robot_id"] for r in await conn.fetch("SELECT robot_id FROM robot")]

    def actions(self) -> None:
        for robot in self.robots:
            if self.service.owns(robot):
                self.service.acted[robot] = self.service.acted.get(robot, 0) + 1

    def rule_generation(self) -> list[Rule]:
        return [self.clone()]


class CounterService(ScenarioService):
    service = SERVICE

    def __init__(self, runtime: Runtime) -> None:
        super().__init__(runtime)
        self.acted: dict[str, int] = {}
        self.changes: list[tuple[frozenset[str], frozenset[str]]] = []
        self.first_activation_owned: frozenset[str] | None = None

    def seed(self) -> None:
        self.engine.add_meta(lambda: CountOwned(self))

    def on_ownership_change(self, gained: frozenset[str], lost: frozenset[str]) -> None:
        self.changes.append((gained, lost))
        super().on_ownership_change(gained, lost)


def config(
    db_url: str, zenoh: ZenohSettings, instance: str, *, leases: bool = True
) -> ServiceConfig:
    return ServiceConfig(
        service=SERVICE,
        database_url=db_url,
        zenoh=zenoh,
        engine=EngineSettings(period_s=0.1),
        leases=LeaseSettings(enabled=leases, period_s=0.2, timeout_s=2.0),
        instance=instance,
    )


async def test_a_lone_replica_owns_every_robot_from_its_first_activation(
    conn: asyncpg.Connection, db_url: str, zenoh_settings: ZenohSettings
) -> None:
    await conn.executemany("INSERT INTO robot (robot_id) VALUES ($1)", [("r1",), ("r2",)])
    cfg = config(db_url, zenoh_settings, "one")
    async with running_service(CounterService, cfg, settle_s=0) as service:
        assert isinstance(service, CounterService)
        await eventually(lambda: service.engine.counters.activations >= 1, within=5)
        # the first activation already acted for both: leases were taken before it ran
        assert service.owned_robots() == frozenset({"r1", "r2"})
        assert set(service.acted) == {"r1", "r2"}
        # each reported gained as its lock was taken, before any activation could see it
        assert {gained for gained, _ in service.changes[:2]} == {
            frozenset({"r1"}),
            frozenset({"r2"}),
        }
        assert not any(lost for _, lost in service.changes[:2])
        # a robot registered later (with its notification) is taken and served
        runtime = await Runtime.open(replace(cfg, service="writer", instance="w"))
        try:
            await runtime.database.write(
                keys.ROBOT, "r3", "INSERT INTO robot (robot_id) VALUES ('r3')"
            )
            await eventually(lambda: service.acted.get("r3", 0) > 0, within=5, what="r3 served")
        finally:
            await runtime.close()
    # a clean stop gave every robot back
    assert await ownership(conn, SERVICE) == {"r1": None, "r2": None, "r3": None}


async def test_two_replicas_split_the_robots_and_one_takes_over_when_the_other_stops(
    conn: asyncpg.Connection, db_url: str, zenoh_settings: ZenohSettings
) -> None:
    robots = ["r1", "r2", "r3", "r4"]
    await conn.executemany("INSERT INTO robot (robot_id) VALUES ($1)", [(r,) for r in robots])
    async with running_service(CounterService, config(db_url, zenoh_settings, "a")) as a:
        async with running_service(CounterService, config(db_url, zenoh_settings, "b")) as b:

            def split() -> bool:
                mine = a.owned_robots() or frozenset()
                theirs = b.owned_robots() or frozenset()
                return len(mine) == len(theirs) == 2 and not mine & theirs

            await eventually(split, within=15, what="a 2/2 split")
            assert await ownership(conn, SERVICE) == {
                **dict.fromkeys(a.owned_robots() or (), "a"),
                **dict.fromkeys(b.owned_robots() or (), "b"),
            }
            assert not any(a.owns(r) and b.owns(r) for r in robots)
            b_robots = b.owned_robots() or frozenset()
            assert isinstance(a, CounterService)
            before = {r: a.acted.get(r, 0) for r in b_robots}
        # b stopped cleanly: a takes its robots and its rules act for them at once
        await eventually(lambda: a.owned_robots() == frozenset(robots), within=5, what="takeover")
        await eventually(
            lambda: all(a.acted.get(r, 0) > before[r] for r in b_robots), within=5, what="served"
        )


async def test_with_leases_off_every_replica_handles_every_robot(
    conn: asyncpg.Connection, db_url: str, zenoh_settings: ZenohSettings
) -> None:
    await conn.execute("INSERT INTO robot (robot_id) VALUES ('r1')")
    cfg = config(db_url, zenoh_settings, "x", leases=False)
    async with running_service(CounterService, cfg, settle_s=0.2) as service:
        assert service.leases is None and service.owns("r1") and service.owned_robots() is None
        await asyncio.sleep(0)
    held = await conn.fetchval("SELECT count(*) FROM robot_lease")
    assert held == 0

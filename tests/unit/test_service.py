"""The scenario-service skeleton against real Postgres and Zenoh: wake, fallback, shutdown."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator

import asyncpg
import pytest

from common import bus
from common.config import EngineSettings, ServiceConfig, ZenohSettings
from common.contract import keys
from common.engine import Behaviour, Rule
from common.runtime import Runtime
from common.service import ScenarioService


class GoalWatcher(Rule):
    """A meta rule that records, with the time it saw it, every new goal id."""

    scenario = "watch_goals"
    meta = True
    watches = (keys.GOAL,)

    def __init__(self, service: WatchService) -> None:
        self.service = service

    async def data_acquisition(self) -> None:
        async with self.service.runtime.database.pool.acquire() as conn:
            self.newest = await conn.fetchval("SELECT max(id) FROM goal")

    def activation_guards(self) -> bool:
        return self.newest is not None and self.newest not in self.service.seen

    def actions(self) -> None:
        self.service.seen[self.newest] = time.monotonic()

    def rule_generation(self) -> list[Rule]:
        return [self.clone()]


class WatchService(ScenarioService):
    service = "watcher"

    def __init__(self, runtime: Runtime) -> None:
        super().__init__(runtime)
        self.seen: dict[int, float] = {}

    def seed(self) -> None:
        self.engine.add_meta(lambda: GoalWatcher(self))


async def started_service(
    db_url: str, zenoh: ZenohSettings, period_s: float
) -> tuple[WatchService, asyncio.Event, asyncio.Task[None]]:
    config = ServiceConfig(
        service="watcher",
        database_url=db_url,
        zenoh=zenoh,
        engine=EngineSettings(period_s=period_s),
        stats_period_s=0.2,
        instance="test-1",
    )
    runtime = await Runtime.open(config)
    service = WatchService(runtime)
    stop = asyncio.Event()
    task = asyncio.create_task(service.run(stop))
    await asyncio.sleep(0.3)  # subscriptions reach the router
    return service, stop, task


@pytest.fixture
async def writer(db_url: str, zenoh_settings: ZenohSettings) -> AsyncIterator[Runtime]:
    runtime = await Runtime.open(
        ServiceConfig(service="writer", database_url=db_url, zenoh=zenoh_settings)
    )
    await runtime.database.write(keys.ROBOT, "r1", "INSERT INTO robot (robot_id) VALUES ('r1')")
    yield runtime
    await runtime.close()


async def insert_goal(runtime: Runtime, x: float, *, notify: bool) -> int:
    sql = "INSERT INTO goal (robot_id, x, y, status) VALUES ('r1', $1, 0, 'reached') RETURNING id"
    if notify:
        return int(await runtime.database.write(keys.GOAL, "r1", sql, x))
    async with runtime.database.pool.acquire() as conn:
        return int(await conn.fetchval(sql, x))


async def wait_seen(service: WatchService, goal_id: int, limit_s: float) -> float:
    deadline = time.monotonic() + limit_s
    while goal_id not in service.seen:
        if time.monotonic() > deadline:
            raise AssertionError(f"goal {goal_id} not seen within {limit_s} s")
        await asyncio.sleep(0.001)
    return service.seen[goal_id]


async def test_a_notification_wakes_the_engine_long_before_f(
    db_url: str, zenoh_settings: ZenohSettings, writer: Runtime
) -> None:
    service, stop, task = await started_service(db_url, zenoh_settings, period_s=30.0)
    try:
        for x in (1.0, 2.0, 3.0):
            written = time.monotonic()
            goal_id = await insert_goal(writer, x, notify=True)
            seen = await wait_seen(service, goal_id, limit_s=5.0)
            assert seen - written < 5.0  # F is 30 s: only a notification explains this
        assert service.engine.counters.woken_by_notification >= 3
    finally:
        stop.set()
        await asyncio.wait_for(task, 10)
        await service.runtime.close()


async def test_a_lost_notification_is_recovered_by_the_period_f(
    db_url: str, zenoh_settings: ZenohSettings, writer: Runtime
) -> None:
    service, stop, task = await started_service(db_url, zenoh_settings, period_s=0.2)
    try:
        goal_id = await insert_goal(writer, 1.0, notify=False)  # no notification at all
        await wait_seen(service, goal_id, limit_s=5.0)
        assert service.engine.counters.woken_by_period >= 1
    finally:
        stop.set()
        await asyncio.wait_for(task, 10)
        await service.runtime.close()


async def test_the_service_publishes_liveliness_and_engine_stats_and_stops_cleanly(
    db_url: str, zenoh_settings: ZenohSettings, writer: Runtime
) -> None:
    service, stop, task = await started_service(db_url, zenoh_settings, period_s=0.05)
    try:
        replies = await asyncio.to_thread(
            lambda: list(writer.zenoh.liveliness().get(keys.alive_watch("watcher"), timeout=2))
        )
        alive = [str(r.ok.key_expr) for r in replies if r.ok is not None]
        assert alive == [keys.alive_key("watcher", "test-1")]
        await asyncio.sleep(0.5)
    finally:
        stop.set()
        await asyncio.wait_for(task, 10)  # drains and writes the statistics a last time
        executed = service.engine.stats_for(GoalWatcher).executed
        await service.runtime.close()
    conn = await asyncpg.connect(db_url)
    try:
        row = await conn.fetchrow(
            "SELECT * FROM engine_stats WHERE service='watcher' AND instance='test-1'"
        )
    finally:
        await conn.close()
    assert row is not None and row["rule_type"] == "GoalWatcher"
    assert row["executed"] == executed > 3  # the final write saw the drained engine
    assert row["scenario"] == "watch_goals"
    replies = await asyncio.to_thread(
        lambda: list(writer.zenoh.liveliness().get(keys.alive_watch("watcher"), timeout=1))
    )
    assert [r for r in replies if r.ok is not None] == []  # the token went with the service


class Lingering(Behaviour[str, str]):
    """A long-lived rule that only records how it ended."""

    scenario = "linger"

    def __init__(self) -> None:
        super().__init__("r1", "spec")
        self.ended: list[str] = []

    def terminate(self, why: str) -> None:
        self.ended.append(why)


async def test_a_stopping_service_terminates_the_behaviours_still_running(
    db_url: str, zenoh_settings: ZenohSettings, writer: Runtime
) -> None:
    service, stop, task = await started_service(db_url, zenoh_settings, period_s=0.05)
    lingering = Lingering()
    lingering.start()
    service.engine.add(lingering)
    try:
        await asyncio.sleep(0.3)  # a few activations: it stays queued, the same object
        engine = service.engine  # (its steps never await: it is in one queue or the other)
        assert lingering.live and lingering in (*engine.current, *engine.next)
    finally:
        stop.set()
        await asyncio.wait_for(task, 10)
        await service.runtime.close()
    assert lingering.ended == ["the service stopped"] and not lingering.live


async def test_notifications_decode_back_to_what_was_sent() -> None:
    note = bus.Notification(keys.ODOMETRY, "r7", 12345)
    assert bus.Notification.decode(keys.notify_key(keys.ODOMETRY, "r7"), note.encode()) == note
    glob = bus.Notification(keys.STRATEGY, None, None)
    assert bus.Notification.decode(keys.notify_key(keys.STRATEGY), glob.encode()) == glob

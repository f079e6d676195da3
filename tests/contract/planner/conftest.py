"""Fixtures for the planner's contract tests: the planner alone, fed as a foreign client would.

``world`` plays every other party: it writes robot, map, charging_station, strategy,
active_strategy, goal, odometry and battery rows with plain SQL, publishes the change
notifications with a plain ``bus.Notifier``, and publishes sim time on ``pnav/sim/clock``
(1 sim s per wall s). While a test runs it keeps writing the robot's current pose as fresh
odometry at 10 Hz, as the bridge would. Nothing is mocked.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator, Callable
from typing import Any

import asyncpg
import pytest

from common import bus
from common.config import EngineSettings, ServiceConfig, ZenohSettings
from common.contract import keys
from common.db import Database, create_pool
from pnav._testing import as_service_role, eventually, publish_clock, running_service
from services.planner.service import PlannerService

ROBOT = "r1"


class World:
    """The planner's surroundings: database rows, notifications, sim time, odometry."""

    def __init__(self, db: Database, session: Any) -> None:
        self.db = db
        self.session = session
        self.pose = (0.0, 0.0, 0.0)
        self.streaming = True
        self._t0 = time.monotonic()
        self._tasks: list[asyncio.Task[None]] = []

    def now(self) -> float:
        return 100.0 + time.monotonic() - self._t0

    async def start(self) -> None:
        self._tasks = [asyncio.create_task(self._clock()), asyncio.create_task(self._odometry())]

    async def stop(self) -> None:
        for task in self._tasks:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task

    async def _clock(self) -> None:
        while True:
            publish_clock(self.session, self.now())
            await asyncio.sleep(0.05)

    async def _odometry(self) -> None:
        while True:
            if self.streaming:
                await self.odometry(*self.pose)
            await asyncio.sleep(0.1)

    # -- writes, each followed by its notification ----------------------------------------
    async def execute(self, table: str, robot: str | None, sql: str, *args: Any) -> Any:
        return await self.db.write(table, robot, sql, *args)

    async def robot(self, world: str | None = None) -> None:
        await self.execute(
            keys.ROBOT, ROBOT, "INSERT INTO robot (robot_id, world) VALUES ($1, $2)", ROBOT, world
        )

    async def odometry(self, x: float, y: float, yaw: float) -> int:
        return int(
            await self.execute(
                keys.ODOMETRY,
                ROBOT,
                "INSERT INTO odometry (robot_id, stamp, x, y, yaw, linear_mps, angular_rps) "
                "VALUES ($1, $2, $3, $4, $5, 0, 0) RETURNING id",
                ROBOT,
                self.now(),
                x,
                y,
                yaw,
            )
        )

    async def battery(self, energy_wh: float, capacity_wh: float = 19.98) -> int:
        return int(
            await self.execute(
                keys.BATTERY,
                ROBOT,
                "INSERT INTO battery (robot_id, stamp, energy_wh, capacity_wh, percentage) "
                "VALUES ($1, $2, $3, $4, $5) RETURNING id",
                ROBOT,
                self.now(),
                energy_wh,
                capacity_wh,
                100.0 * energy_wh / capacity_wh,
            )
        )

    async def strategy(self, code: str) -> None:
        await self.execute(
            keys.ACTIVE_STRATEGY,
            ROBOT,
            "INSERT INTO active_strategy (robot_id, strategy_code, source, stamp) "
            "VALUES ($1, $2, 'user', $3) ON CONFLICT (robot_id) DO UPDATE SET "
            "strategy_code = EXCLUDED.strategy_code, stamp = EXCLUDED.stamp, updated_at = now()",
            ROBOT,
            code,
            self.now(),
        )

    async def goal(self, x: float, y: float, tolerance: float = 0.15) -> int:
        """A new active goal, superseding the previous one in the same transaction."""
        async with self.db.transaction() as tx:
            await tx.conn.execute(
                "UPDATE goal SET status = 'superseded', finished_stamp = $2 "
                "WHERE robot_id = $1 AND status = 'active'",
                ROBOT,
                self.now(),
            )
            goal_id = int(
                await tx.conn.fetchval(
                    "INSERT INTO goal (robot_id, x, y, tolerance_m, stamp) "
                    "VALUES ($1, $2, $3, $4, $5) RETURNING id",
                    ROBOT,
                    x,
                    y,
                    tolerance,
                    self.now(),
                )
            )
            tx.changed(keys.GOAL, ROBOT, goal_id)
        return goal_id

    # -- reads -------------------------------------------------------------------------------
    async def recommendations(self, after: int = 0, kind: str = "robot") -> list[asyncpg.Record]:
        return list(
            await self.db.pool.fetch(
                "SELECT * FROM command_recommendation WHERE robot_id = $1 AND kind = $2 "
                "AND id > $3 ORDER BY id",
                ROBOT,
                kind,
                after,
            )
        )

    async def newest_id(self) -> int:
        return int(
            await self.db.pool.fetchval("SELECT coalesce(max(id), 0) FROM command_recommendation")
        )

    async def next_recommendation(
        self,
        check: Callable[[asyncpg.Record], bool],
        after: int = 0,
        kind: str = "robot",
        within: float = 10.0,
        what: str = "",
    ) -> asyncpg.Record:
        """The first recommendation newer than ``after`` for which ``check`` holds."""

        async def find() -> asyncpg.Record | None:
            return next((r for r in await self.recommendations(after, kind) if check(r)), None)

        found: asyncpg.Record = await eventually(find, within, what=what or "a recommendation")
        return found


@pytest.fixture
async def world(db_url: str, zenoh_settings: ZenohSettings) -> AsyncIterator[World]:
    session = bus.open_session(zenoh_settings)
    pool = await create_pool(db_url, max_size=3)
    db = Database(pool, bus.Notifier(session))
    w = World(db, session)
    await w.robot()
    await w.start()
    try:
        yield w
    finally:
        await w.stop()
        db.notifier.close()
        await db.close()  # its lane, then the pool
        session.close()


@pytest.fixture
async def planner(
    world: World, db_url: str, zenoh_settings: ZenohSettings
) -> AsyncIterator[PlannerService]:
    config = ServiceConfig(
        service="planner",
        database_url=await as_service_role(db_url, "planner"),  # exactly its grants
        zenoh=zenoh_settings,
        engine=EngineSettings(period_s=0.05),
        stats_period_s=5.0,
        instance="planner-test",
    )
    async with running_service(PlannerService, config) as service:
        assert isinstance(service, PlannerService)
        yield service

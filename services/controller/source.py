"""The controller's raw reads and writes of the contract: :class:`ControllerSource` (a
Protocol) and :class:`PgControllerSource`, them in Postgres (through
``common.contract.records``). pnav/monolith/memory_controller.py has them in memory;
services/controller/store.py keeps what notifications told the service and gives the rules
their host."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from common.contract import records
from common.contract.models import RegisteredModel, read_models
from common.contract.planned_path import PlannedPath, newest_planned_path
from common.contract.recommendations import (
    Recommendation,
    write_recommendation,
    write_recommendations,
)
from common.contract.records import ActiveStrategy, LaserScan, Odometry, Robot
from common.db import Database

ScanAndOdometry = tuple[LaserScan | None, Odometry | None]

# how long a read of the strategies waits behind a lock before the ones held serve
STRATEGY_LOCK_WAIT_MS = 10


class ControllerSource(Protocol):
    """The contract as the controller reads and writes it."""

    async def robots(self) -> list[Robot]: ...

    async def active_strategies(self) -> dict[str, ActiveStrategy]: ...

    async def newest_scan_and_odometry(self, robot_id: str) -> ScanAndOdometry:
        """The robot's newest scan and newest odometry in one round trip (odometry is None
        when there is no scan yet, or no odometry)."""

    async def newest_odometry(self, robot_id: str) -> Odometry | None: ...

    async def newest_odometries(self, robot_ids: Sequence[str]) -> dict[str, Odometry | None]:
        """Each robot's newest odometry (None: none yet), in one round trip."""

    async def newest_planned_path(self, robot_id: str) -> PlannedPath | None:
        """The path in force for the robot (the planner's newest planned_path row)."""

    async def models(self) -> list[RegisteredModel]:
        """The register of learned models (the model table), oldest first per name."""

    async def recommend(self, recommendation: Recommendation) -> int:
        """Write a command_recommendation row (notified after commit); its id."""

    async def recommend_many(self, recommendations: Sequence[Recommendation]) -> list[int | None]:
        """Write rows of distinct (robot, source) in one commit, each notified after it;
        their ids in order (None: refused)."""


class PgControllerSource:
    """:class:`ControllerSource` in Postgres."""

    def __init__(self, db: Database) -> None:
        self.db = db

    async def robots(self) -> list[Robot]:
        return await records.robots(self.db)

    async def active_strategies(self) -> dict[str, ActiveStrategy]:
        # strategy is the one table read here that people may lock (CONTRACT.md, *Roles*):
        # a plain read waits only behind ACCESS EXCLUSIVE, which no service takes while the
        # stack runs, so it may give up long before the pool's lock_timeout, and the
        # activation it runs in (safety_stop's too) barely waits
        async with self.db.pool.acquire() as conn, conn.transaction(readonly=True):
            await conn.execute(f"SET LOCAL lock_timeout = '{STRATEGY_LOCK_WAIT_MS}ms'")
            return await records.active_strategies(conn)

    async def newest_scan_and_odometry(self, robot_id: str) -> ScanAndOdometry:
        return await records.newest_scan_and_odometry(self.db, robot_id)

    async def newest_odometry(self, robot_id: str) -> Odometry | None:
        return await records.newest_odometry(self.db, robot_id)

    async def newest_odometries(self, robot_ids: Sequence[str]) -> dict[str, Odometry | None]:
        return await records.newest_odometries(self.db, robot_ids)

    async def newest_planned_path(self, robot_id: str) -> PlannedPath | None:
        return await newest_planned_path(self.db, robot_id)

    async def models(self) -> list[RegisteredModel]:
        return await read_models(self.db)

    async def recommend(self, recommendation: Recommendation) -> int:
        return await write_recommendation(self.db, recommendation)

    async def recommend_many(self, recommendations: Sequence[Recommendation]) -> list[int | None]:
        return await write_recommendations(self.db, recommendations)

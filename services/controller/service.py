"""The controller service: ``python -m services.controller``.

One Proactive Engine seeded with the meta-controller (meta.py), which starts and ends the
controller scenarios (registry.py) each robot's strategy names. The service is the rules'
:class:`~services.controller.scenario.Host`: sim time, the contract reads, the write.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

from common import log
from common.bus import Notification
from common.contract import keys, records
from common.contract.records import ActiveStrategy, LaserScan, Odometry, Robot
from common.db import Database
from common.runtime import Runtime
from common.service import ScenarioService
from services.controller.meta import ControllerState, MetaController
from services.controller.scenario import Recommendation

logger = logging.getLogger("pnav.controller")

T = TypeVar("T")

# Notifications are hints: a row is read again after this long (wall) even if none came.
RECHECK_S = 0.25
_META_TABLES = frozenset((keys.ACTIVE_STRATEGY, keys.STRATEGY, keys.ROBOT))


async def store_recommendation(db: Database, r: Recommendation) -> int:
    """A scenario's recommendation as a command_recommendation row (notified after commit)."""
    return await records.recommend_velocity(
        db,
        r.robot_id,
        source=r.source,
        priority=r.priority,
        linear=r.linear,
        angular=r.angular,
        stamp=r.stamp,
        ttl_s=r.ttl_s,
        reason=r.reason,
        inputs=r.inputs,
    )


class ControllerService(ScenarioService):
    service = "controller"

    def __init__(self, runtime: Runtime) -> None:
        super().__init__(runtime)
        self.state = ControllerState()
        self._reads: dict[tuple[str, str], tuple[int, Any]] = {}
        # What the notifications announced, written on Zenoh's thread (single stores): the
        # newest laser_scan id per robot, and whether robots or strategies changed. Reads
        # are skipped while nothing newer was announced, so an activation woken by one
        # robot's scan reads that robot's scan only, not every robot's.
        self._announced_scan: dict[str, int | None] = {}
        self._scans: dict[str, tuple[LaserScan | None, float]] = {}
        self._odometry_with_scan: dict[str, tuple[int | None, Odometry | None]] = {}
        self._meta_dirty = True
        self._meta: tuple[list[Robot], dict[str, ActiveStrategy], float] | None = None

    def seed(self) -> None:
        self.engine.add_meta(lambda: MetaController(self, self.state, owns=self.owns))

    def on_ownership_change(self, gained: frozenset[str], lost: frozenset[str]) -> None:
        # The meta-controller ends a lost robot's scenarios in its next run (it only wants
        # owned robots); forget what was read for it, and the scans an earlier tenure
        # recommended on (another replica served the robot since).
        for key in [k for k in self._reads if k[1] in lost]:
            del self._reads[key]
        for robot_id in lost:
            self._scans.pop(robot_id, None)
            self._odometry_with_scan.pop(robot_id, None)
        for key in [k for k in self.state.last_scan if k[0] in gained]:
            del self.state.last_scan[key]
        super().on_ownership_change(gained, lost)

    def on_notification(self, note: Notification) -> None:
        """Note what each notification announces (on the loop, before the engine wakes)."""
        if not note.table:
            self._meta_dirty = True  # unreadable: assume anything changed
            return
        if note.table == keys.LASER_SCAN and note.robot is not None:
            known = self._announced_scan.get(note.robot)
            if note.id is None or known is None or note.id > known:
                # an id-less hint leaves None: "something new", read at the next chance
                self._announced_scan[note.robot] = note.id
            if note.id is None:
                self._scans.pop(note.robot, None)
        elif note.table in _META_TABLES:
            self._meta_dirty = True

    async def _meta_reads(self) -> tuple[list[Robot], dict[str, ActiveStrategy]]:
        meta = self._meta
        if meta is None or self._meta_dirty or time.monotonic() - meta[2] >= RECHECK_S:
            self._meta_dirty = False  # before the reads: a change meanwhile flags it again
            pool = self.runtime.database.pool
            read_at = time.monotonic()
            meta = (await records.robots(pool), await records.active_strategies(pool), read_at)
            self._meta = meta
        return meta[0], meta[1]

    # -- Host ------------------------------------------------------------------------------
    def sim_now(self) -> float | None:
        clock = self.runtime.clock
        return clock.now() if clock.started else None

    async def robots(self) -> list[Robot]:
        return (await self._meta_reads())[0]

    async def active_strategies(self) -> dict[str, ActiveStrategy]:
        return (await self._meta_reads())[1]

    async def newest_scan(self, robot_id: str) -> LaserScan | None:
        cached = self._scans.get(robot_id)
        if cached is not None and time.monotonic() - cached[1] < RECHECK_S:
            scan = cached[0]
            announced = self._announced_scan.get(robot_id, -1)
            if announced is not None and scan is not None and announced <= scan.id:
                return scan  # nothing newer announced since it was read
            if announced == -1 and scan is None:
                return None  # no scan yet, and none announced
        read_at = time.monotonic()
        # the avoid scenarios want the odometry too, for the same scan: one round trip
        scan, odom = await records.newest_scan_and_odometry(self.runtime.database.pool, robot_id)
        self._scans[robot_id] = (scan, read_at)
        self._odometry_with_scan[robot_id] = (scan.id if scan else None, odom)
        if scan is not None and self._announced_scan.get(robot_id, -1) is None:
            self._announced_scan[robot_id] = scan.id  # the id-less hint is answered
        return scan

    async def newest_odometry(self, robot_id: str) -> Odometry | None:
        """The odometry read together with the robot's current scan: the robot's motion at
        the moment that scan was read, which is what a decision about the scan needs (a
        scenario may come to the scan an activation later); otherwise the newest, read once
        per activation."""
        scan = self._scans.get(robot_id)
        with_scan = self._odometry_with_scan.get(robot_id)
        if (
            scan is not None
            and scan[0] is not None
            and with_scan is not None
            and with_scan[0] == scan[0].id
        ):
            return with_scan[1]
        return await self._once_per_activation("odometry", robot_id, records.newest_odometry)

    async def recommend(self, recommendation: Recommendation) -> int:
        r = recommendation
        row_id = await store_recommendation(self.runtime.database, r)
        log.event(
            logger,
            logging.DEBUG,
            "recommended",
            robot=r.robot_id,
            source=r.source,
            id=row_id,
            linear=round(r.linear, 3),
            angular=round(r.angular, 3),
            reason=r.reason,
        )
        return row_id

    async def _once_per_activation(
        self, kind: str, robot_id: str, read: Callable[[Any, str], Awaitable[T]]
    ) -> T:
        """Every scenario of a robot wants the same newest row in one activation: read it
        once. The engine counts activations at their end, so the count names this one."""
        tick = self.engine.counters.activations
        cached = self._reads.get((kind, robot_id))
        if cached is not None and cached[0] == tick:
            value: T = cached[1]
            return value
        value = await read(self.runtime.database.pool, robot_id)
        self._reads[(kind, robot_id)] = (tick, value)
        return value

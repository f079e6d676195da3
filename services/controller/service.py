"""The controller service: ``python -m services.controller``.

One Proactive Engine seeded with the meta-controller (meta.py), which starts and ends the
controller scenarios (registry.py) each robot's strategy names. The service is the rules'
:class:`~services.controller.scenario.Host`: sim time, the contract reads, the write.
"""

from __future__ import annotations

import logging
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

from common import log
from common.contract import records
from common.contract.records import ActiveStrategy, LaserScan, Odometry, Robot
from common.runtime import Runtime
from common.service import ScenarioService
from services.controller.meta import ControllerState, MetaController
from services.controller.scenario import Recommendation

logger = logging.getLogger("pnav.controller")

T = TypeVar("T")


class ControllerService(ScenarioService):
    service = "controller"

    def __init__(self, runtime: Runtime) -> None:
        super().__init__(runtime)
        self.state = ControllerState()
        self._reads: dict[tuple[str, str], tuple[int, Any]] = {}

    def seed(self) -> None:
        self.engine.add_meta(lambda: MetaController(self, self.state, owns=self.owns))

    def on_ownership_change(self, gained: frozenset[str], lost: frozenset[str]) -> None:
        # The meta-controller ends a lost robot's scenarios in its next run (it only wants
        # owned robots); forget what was read for it, and the scans an earlier tenure
        # recommended on (another replica served the robot since).
        for key in [k for k in self._reads if k[1] in lost]:
            del self._reads[key]
        for key in [k for k in self.state.last_scan if k[0] in gained]:
            del self.state.last_scan[key]
        super().on_ownership_change(gained, lost)

    # -- Host ------------------------------------------------------------------------------
    def sim_now(self) -> float | None:
        clock = self.runtime.clock
        return clock.now() if clock.started else None

    async def robots(self) -> list[Robot]:
        return await records.robots(self.runtime.database.pool)

    async def active_strategies(self) -> dict[str, ActiveStrategy]:
        return await records.active_strategies(self.runtime.database.pool)

    async def newest_scan(self, robot_id: str) -> LaserScan | None:
        return await self._once_per_activation("scan", robot_id, records.newest_scan)

    async def newest_odometry(self, robot_id: str) -> Odometry | None:
        return await self._once_per_activation("odometry", robot_id, records.newest_odometry)

    async def recommend(self, recommendation: Recommendation) -> int:
        r = recommendation
        row_id = await records.recommend_velocity(
            self.runtime.database,
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

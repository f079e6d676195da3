"""The controller service in one process: its store Protocol over the in-memory contract.

:class:`MemoryControllerSource` answers the controller's reads and write
(services.controller.source.ControllerSource) from :class:`MemoryContract` rows, as Postgres
answers :class:`~services.controller.source.PgControllerSource`; the service's own
:class:`~services.controller.store.ControllerStore`, with its caches, sits on top, and
:func:`controller_engine` seeds the meta-controller on an engine exactly as
``ControllerService.seed`` does.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from common.contract import keys, models, offers, records
from common.contract.models import RegisteredModel
from common.contract.planned_path import PlannedPath, planned_path_of
from common.contract.recommendations import Recommendation
from common.contract.records import ActiveStrategy, LaserScan, Odometry, Robot, Strategy
from common.controller_core.scenario import installed_scenarios
from common.engine import Engine
from pnav.monolith.contract import MemoryContract, Row
from services.controller.meta import Scenarios, seed_controller
from services.controller.source import ScanAndOdometry
from services.controller.store import ControllerStore

_ROBOT = (
    *("robot_id", "max_linear_mps", "max_angular_rps", "footprint_radius_m"),
    *("battery_capacity_wh", "max_linear_accel_mps2", "max_angular_accel_rps2"),
)
_ODOMETRY = ("id", "robot_id", "stamp", "x", "y", "yaw", "linear_mps", "angular_rps")
_SCAN = ("id", "robot_id", "stamp", "angle_min", "angle_increment", "range_min", "range_max")


def _pick(row: Row, columns: tuple[str, ...]) -> dict[str, Any]:
    return {c: row[c] for c in columns}


def _laser_scan(row: Row) -> LaserScan:
    return LaserScan(**_pick(row, _SCAN), ranges=np.asarray(row["ranges"], dtype=np.float32))


def _odometry(row: Row | None) -> Odometry | None:
    return None if row is None else Odometry(**_pick(row, _ODOMETRY))


class MemoryControllerSource:
    """:class:`~services.controller.source.ControllerSource` over the in-memory contract."""

    def __init__(self, contract: MemoryContract) -> None:
        self.contract = contract

    async def robots(self) -> list[Robot]:
        rows = self.contract[keys.ROBOT].all_rows()
        robots = (
            Robot(
                **_pick(r, _ROBOT),
                footprint_polygon=records.polygon_of(r.get("footprint_polygon")),
            )
            for r in rows
        )
        return sorted(robots, key=lambda r: r.robot_id)

    async def active_strategies(self) -> dict[str, ActiveStrategy]:
        # the strategy join; a robot's newest active_strategy row is its row (an upsert)
        strategies = {r["code"]: r for r in self.contract[keys.STRATEGY].all_rows()}
        out: dict[str, ActiveStrategy] = {}
        for active in self.contract[keys.ACTIVE_STRATEGY].all_rows():
            row = strategies.get(active["strategy_code"])
            if row is None:
                continue
            strategy = Strategy(
                code=row["code"],
                planner_scenario=row["planner_scenario"],
                controller_scenarios=tuple(row["controller_scenarios"]),
                params=dict(row["params"] or {}),
            )
            robot_id = active["robot_id"]
            out[robot_id] = ActiveStrategy(
                robot_id, strategy, active["resume_code"], active["source"]
            )
        return out

    async def newest_scan_and_odometry(self, robot_id: str) -> ScanAndOdometry:
        scan = self.contract[keys.LASER_SCAN].newest(robot_id)
        if scan is None:
            return None, None
        return _laser_scan(scan), _odometry(self.contract[keys.ODOMETRY].newest(robot_id))

    async def newest_odometry(self, robot_id: str) -> Odometry | None:
        return _odometry(self.contract[keys.ODOMETRY].newest(robot_id))

    async def newest_planned_path(self, robot_id: str) -> PlannedPath | None:
        row = self.contract[keys.PLANNED_PATH].newest(robot_id)
        return None if row is None else planned_path_of(row)

    async def newest_odometries(self, robot_ids: Sequence[str]) -> dict[str, Odometry | None]:
        return {robot_id: await self.newest_odometry(robot_id) for robot_id in robot_ids}

    async def models(self) -> list[RegisteredModel]:
        table = self.contract.tables.get(keys.MODEL)
        return [] if table is None else [models.of_row(r) for r in table.all_rows()]

    async def recommend(self, recommendation: Recommendation) -> int:
        return self.contract.insert_recommendation(recommendation)

    async def recommend_many(self, recommendations: Sequence[Recommendation]) -> list[int | None]:
        return [await self.recommend(r) for r in recommendations]


def controller_engine(
    contract: MemoryContract,
    engine: Engine,
    now: Callable[[], float],
    scenarios: Scenarios | None = None,
) -> ControllerStore:
    """Seed the controller's meta rule on ``engine`` as the service does, over ``contract``
    at sim time ``now`` (which its caches count in too); the store, to be told every change
    the contract announces (``store.note``). ``scenarios``: the installed ones if None."""
    store = ControllerStore(MemoryControllerSource(contract), clock=now)
    engine.at_activation_end(store.defer_recommendations())
    found = installed_scenarios() if scenarios is None else scenarios
    seed_controller(engine, store, found)
    contract.offer(offers.CONTROLLER, found)  # as the service's start publishes them
    return store

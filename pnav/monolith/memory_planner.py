"""The planner in the monolith: its store on the in-memory contract, its engine seeded as the
service seeds it.

:class:`MemoryPlannerSource` answers the planner's reads and writes
(``services.planner.source.PlannerSource``) from :class:`MemoryContract`'s rows, each as
Postgres would answer the statement ``PgPlannerSource`` sends (the same rows, in the same
order, as the same records); a write inserts or updates the row, then notifies, as
``Database.write`` does after its commit. :func:`planner_engine` builds the real
``PlannerStore`` on it, on sim time, so the planner's caches and gates run here as in a
lockstep stack.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from common.contract import keys, offers, records
from common.contract.recommendations import Recommendation
from common.contract.zones import Zone
from common.engine import Engine
from common.planner_core.scenario import RobotInfo
from pnav.monolith.contract import MemoryContract, Row
from services.planner import meta
from services.planner.published_path import PathRow
from services.planner.store import PlannerStore
from services.planner.world_model import MapRow, Station


def _strategy(row: Row) -> records.Strategy:
    return records.Strategy(
        code=row["code"],
        planner_scenario=row["planner_scenario"],
        controller_scenarios=tuple(row["controller_scenarios"]),
        params=dict(row["params"] or {}),
    )


# the goal_waypoint columns records.Waypoint holds
_WAYPOINT = ("seq", "x", "y", "tolerance_m", "yaw", "yaw_tolerance_rad", "stop", "status")


class MemoryPlannerSource:
    """``PlannerSource`` over the in-memory contract."""

    def __init__(self, contract: MemoryContract) -> None:
        self.contract = contract

    def _newest(self, table: str, robot_id: str) -> Row | None:
        return self.contract[table].newest(robot_id)

    async def robots(self) -> list[RobotInfo]:
        return [
            RobotInfo(
                r["robot_id"],
                r["world"],
                r["max_linear_mps"],
                r["max_angular_rps"],
                r["footprint_radius_m"],
                records.polygon_of(r.get("footprint_polygon")),
            )
            for r in self.contract[keys.ROBOT].all_rows()
        ]

    async def map_versions(self) -> dict[str, str]:
        return {r["map_id"]: str(r["loaded_at"]) for r in self.contract[keys.MAP].all_rows()}

    async def map(self, map_id: str, version: str) -> MapRow | None:
        row = next((r for r in self.contract[keys.MAP].all_rows() if r["map_id"] == map_id), None)
        if row is None:
            return None
        return MapRow.of(map_id, version, row)

    async def stations(self) -> list[Station]:
        rows = sorted(
            self.contract[keys.CHARGING_STATION].all_rows(), key=lambda r: r["station_id"]
        )
        return [Station(r["station_id"], r["map_id"], r["x"], r["y"], r["radius_m"]) for r in rows]

    async def zones(self) -> list[Zone]:
        rows = sorted(self.contract[keys.ZONE].all_rows(), key=lambda r: r["name"])
        return [Zone.of_row(r) for r in rows]

    async def active_strategies(self) -> dict[str, records.ActiveStrategy]:
        # the join of records.active_strategies; a robot's newest row wins (the table keeps
        # one per robot, which the monolith updates by inserting)
        strategies = {r["code"]: r for r in self.contract[keys.STRATEGY].all_rows()}
        out: dict[str, records.ActiveStrategy] = {}
        for active in self.contract[keys.ACTIVE_STRATEGY].all_rows():
            strategy = strategies.get(active["strategy_code"])
            if strategy is not None:
                robot_id = active["robot_id"]
                out[robot_id] = records.ActiveStrategy(
                    robot_id, _strategy(strategy), active["resume_code"], active["source"]
                )
        return out

    async def active_goal(
        self, robot_id: str, known: records.Goal | None = None
    ) -> records.Goal | None:
        for r in self.contract[keys.GOAL].rows(robot_id):
            if r["status"] == "active":
                route = sorted(self._waypoints(robot_id, r["id"]), key=lambda w: w["seq"])
                return records.Goal(
                    r["id"], r["robot_id"], r["x"], r["y"], r["tolerance_m"],
                    r.get("yaw"), r.get("yaw_tolerance_rad"),
                    tuple(records.Waypoint(**{k: w[k] for k in _WAYPOINT}) for w in route),
                    len(route),
                )  # fmt: skip
        return None

    def _waypoints(self, robot_id: str, goal_id: int) -> list[Row]:
        # goal_waypoint rows are kept under their goal's robot (a column the table lacks)
        return [
            w for w in self.contract[keys.GOAL_WAYPOINT].rows(robot_id) if w["goal_id"] == goal_id
        ]

    # a row of the in-memory contract holds what a row image holds: the image's parsers
    async def newest_odometry(self, robot_id: str) -> records.Odometry | None:
        r = self._newest(keys.ODOMETRY, robot_id)
        return None if r is None else records.odometry_of(r)

    async def newest_scan(self, robot_id: str) -> records.LaserScan | None:
        r = self._newest(keys.LASER_SCAN, robot_id)
        return None if r is None else records.laser_scan_of(r)

    async def newest_battery(self, robot_id: str) -> records.Battery | None:
        r = self._newest(keys.BATTERY, robot_id)
        return None if r is None else records.battery_of(r)

    async def mark_reached(self, goal_id: int, robot_id: str, stamp: float) -> bool:
        goal = self.contract[keys.GOAL].by_id.get(goal_id)
        updated = goal is not None and goal["status"] == "active"
        if goal is not None and updated:
            goal.update(status="reached", finished_stamp=stamp)
        # notified either way, as Database.write does (with no id when nothing changed)
        self.contract.changed(keys.GOAL, robot_id, goal_id if updated else None)
        return updated

    async def mark_failed(
        self, goal_id: int, robot_id: str, reason: str, stamp: float, strategy: str | None = None
    ) -> bool:
        goal = self.contract[keys.GOAL].by_id.get(goal_id)
        updated = goal is not None and goal["status"] == "active"
        if updated and strategy is not None:
            active = self.contract[keys.ACTIVE_STRATEGY].newest(robot_id)
            updated = active is not None and active["strategy_code"] == strategy
        if goal is not None and updated:
            goal.update(status="failed", reason=reason, finished_stamp=stamp)
        self.contract.changed(keys.GOAL, robot_id, goal_id if updated else None)
        return updated

    async def mark_waypoint(
        self, goal_id: int, seq: int, robot_id: str, status: str, reason: str | None, stamp: float
    ) -> bool:
        goal = self.contract[keys.GOAL].by_id.get(goal_id)
        rows = [w for w in self._waypoints(robot_id, goal_id) if w["seq"] == seq]
        updated = bool(rows) and rows[0]["status"] == "pending"
        updated = updated and goal is not None and goal["status"] == "active"
        if updated:
            rows[0].update(status=status, reason=reason, reached_stamp=stamp)
        self.contract.changed(keys.GOAL_WAYPOINT, robot_id, goal_id if updated else None)
        return updated

    async def live_system(self, robot_id: str, command: str, now: float) -> float | None:
        expiries = [
            float(r["expires_stamp"])
            for r in self.contract.live_recommendations(robot_id, now)
            if r["kind"] == "system" and r["system_command"] == command
        ]
        return max(expiries) if expiries else None

    async def recommend(self, rec: Recommendation) -> int:
        return self.contract.insert_recommendation(rec)

    async def recommend_many(self, recs: Sequence[Recommendation]) -> list[int | None]:
        return [await self.recommend(rec) for rec in recs]

    async def publish_path(self, path: PathRow) -> int:
        return self.contract.insert(keys.PLANNED_PATH, dict(path))

    async def live_offers(self) -> offers.Offers:
        return self.contract.offers()


def planner_engine(
    contract: MemoryContract, engine: Engine, now: Callable[[], float]
) -> PlannerStore:
    """Seed the meta-planner on ``engine`` as ``PlannerService.seed`` does, with the move
    scenarios installed, and return its store: on sim time for its gates too (a lockstep
    run's clock), so a run depends on the sim alone. Hand it every change the contract
    announces (``store.note``)."""
    store = PlannerStore(MemoryPlannerSource(contract), now, now, lambda: True)
    engine.at_activation_end(store.defer_recommendations())
    rules = meta.seed(engine, store, meta.move_scenarios())
    contract.offer(offers.PLANNER, rules.scenarios)  # as the service's start publishes them
    return store

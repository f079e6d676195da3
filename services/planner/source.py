"""The planner's raw reads and writes of the contract: :class:`PlannerSource` (a Protocol)
and :class:`PgPlannerSource`, them in SQL on an asyncpg pool, the planner's only SQL.
pnav.monolith.memory_planner has the in-memory source; services/planner/store.py keeps what
notifications told the service and gives the rules their view."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from common.contract import keys, offers, planned_path, records, zones
from common.contract.offers import Offers
from common.contract.recommendations import (
    Recommendation,
    write_recommendation,
    write_recommendations,
)
from common.contract.zones import Zone
from common.db import Database
from common.planner_core.scenario import RobotInfo
from services.planner.published_path import PathRow
from services.planner.view import Rows
from services.planner.world_model import MapRow, Station

ROBOTS_SQL = (
    "SELECT robot_id, world, max_linear_mps, max_angular_rps, footprint_radius_m, "
    "footprint_polygon FROM robot"
)
MAP_VERSIONS_SQL = "SELECT map_id, loaded_at FROM map"
MAP_SQL = (
    "SELECT resolution_m, origin_x, origin_y, origin_yaw, width, height, grid "
    "FROM map WHERE map_id = $1"
)
STATIONS_SQL = "SELECT station_id, map_id, x, y, radius_m FROM charging_station ORDER BY station_id"
MARK_REACHED_SQL = (
    "UPDATE goal SET status = 'reached', finished_stamp = $2 "
    "WHERE id = $1 AND status = 'active' RETURNING id"
)
MARK_FAILED_SQL = (
    "UPDATE goal SET status = 'failed', reason = $3, finished_stamp = $2 "
    "WHERE id = $1 AND status = 'active' AND ($4::text IS NULL OR EXISTS ("
    "SELECT 1 FROM active_strategy a WHERE a.robot_id = goal.robot_id "
    "AND a.strategy_code = $4)) RETURNING id"
)
MARK_WAYPOINT_SQL = (
    "UPDATE goal_waypoint w SET status = $3, reason = $4, reached_stamp = $5 FROM goal g "
    "WHERE w.goal_id = $1 AND w.seq = $2 AND w.status = 'pending' "
    "AND g.id = w.goal_id AND g.status = 'active' RETURNING w.goal_id"
)
LIVE_SYSTEM_SQL = (
    "SELECT max(expires_stamp) FROM command_recommendation WHERE robot_id = $1 "
    "AND kind = 'system' AND system_command = $2 AND expires_stamp > $3"
)


class PlannerSource(Rows, Protocol):
    """The planner's reads and writes of the contract, typed (CONTRACT.md has the tables)."""

    async def robots(self) -> list[RobotInfo]: ...

    async def map_versions(self) -> dict[str, str]:
        """map_id -> its version (loaded_at, as text)."""

    async def map(self, map_id: str, version: str) -> MapRow | None: ...

    async def stations(self) -> list[Station]:
        """By station id."""

    async def active_strategies(self) -> dict[str, records.ActiveStrategy]: ...

    async def zones(self) -> list[Zone]:
        """Every keepout and speed zone, by name."""

    async def active_goal(
        self, robot_id: str, known: records.Goal | None = None
    ) -> records.Goal | None:
        """The robot's active goal with its route (``known``: as read last; its waypoints
        are kept while their count is unchanged)."""

    async def live_system(self, robot_id: str, command: str, now: float) -> float | None:
        """The newest expiry after ``now`` of the robot's ``command`` recommendations."""

    async def recommend(self, rec: Recommendation) -> int:
        """Write a command_recommendation row and notify; its id."""

    async def recommend_many(self, recs: Sequence[Recommendation]) -> list[int | None]:
        """Write rows of distinct (robot, source) in one commit, each notified after it;
        their ids in order (None: refused)."""

    async def publish_path(self, path: PathRow) -> int:
        """Write a planned_path row (``path``: its contract columns) and notify; its id."""

    async def live_offers(self) -> Offers:
        """What the live planners and controllers offer (scenario_offer)."""


class PgPlannerSource:
    """:class:`PlannerSource` on Postgres: ``Database.write`` notifies after each write."""

    def __init__(self, db: Database) -> None:
        self.db = db

    async def robots(self) -> list[RobotInfo]:
        return [
            RobotInfo(
                **{**dict(r), "footprint_polygon": records.polygon_of(r["footprint_polygon"])}
            )
            for r in await self.db.fetch(ROBOTS_SQL)
        ]

    async def map_versions(self) -> dict[str, str]:
        rows = await self.db.fetch(MAP_VERSIONS_SQL)
        return {r["map_id"]: str(r["loaded_at"]) for r in rows}

    async def map(self, map_id: str, version: str) -> MapRow | None:
        row = await self.db.fetchrow(MAP_SQL, map_id)
        if row is None:
            return None
        return MapRow.of(map_id, version, row)

    async def stations(self) -> list[Station]:
        return [Station(**dict(r)) for r in await self.db.fetch(STATIONS_SQL)]

    async def active_strategies(self) -> dict[str, records.ActiveStrategy]:
        return await records.active_strategies(self.db)

    async def zones(self) -> list[Zone]:
        return await zones.read_zones(self.db)

    async def active_goal(
        self, robot_id: str, known: records.Goal | None = None
    ) -> records.Goal | None:
        return await records.active_goal(self.db, robot_id, known)

    async def newest_odometry(self, robot_id: str) -> records.Odometry | None:
        return await records.newest_odometry(self.db, robot_id)

    async def newest_scan(self, robot_id: str) -> records.LaserScan | None:
        return await records.newest_scan(self.db, robot_id)

    async def newest_battery(self, robot_id: str) -> records.Battery | None:
        return await records.newest_battery(self.db, robot_id)

    async def mark_reached(self, goal_id: int, robot_id: str, stamp: float) -> bool:
        updated = await self.db.write(keys.GOAL, robot_id, MARK_REACHED_SQL, goal_id, stamp)
        return updated is not None

    async def mark_failed(
        self, goal_id: int, robot_id: str, reason: str, stamp: float, strategy: str | None = None
    ) -> bool:
        sql, args = MARK_FAILED_SQL, (goal_id, stamp, reason, strategy)
        return await self.db.write(keys.GOAL, robot_id, sql, *args) is not None

    async def mark_waypoint(
        self, goal_id: int, seq: int, robot_id: str, status: str, reason: str | None, stamp: float
    ) -> bool:
        args = (goal_id, seq, status, reason, stamp)
        return (
            await self.db.write(keys.GOAL_WAYPOINT, robot_id, MARK_WAYPOINT_SQL, *args) is not None
        )

    async def live_system(self, robot_id: str, command: str, now: float) -> float | None:
        value = await self.db.fetchval(LIVE_SYSTEM_SQL, robot_id, command, now)
        return float(value) if value is not None else None

    async def recommend(self, rec: Recommendation) -> int:
        return await write_recommendation(self.db, rec)

    async def recommend_many(self, recs: Sequence[Recommendation]) -> list[int | None]:
        return await write_recommendations(self.db, recs)

    async def publish_path(self, path: PathRow) -> int:
        return await planned_path.write_planned_path(self.db, path)

    async def live_offers(self) -> Offers:
        return await offers.live_offers(self.db)

"""The dashboard's one data path: its SQL (:class:`PgDashboardSource`) and its store.

- :class:`DashboardSource`: the typed reads and the writes, as a Protocol; the Postgres one
  is the only place the dashboard speaks SQL. It writes only the people's tables (goal,
  user_command, strategy), each followed by its notification, as ``pnav goal`` does.
- :class:`DashboardStore`: what the page shows, fed by every change notification
  (:meth:`DashboardStore.note`): a row image is used as it comes (odometry, scans, battery,
  decisions, recommendations), anything else marks what to read at the next
  :meth:`DashboardStore.flush`. Every table is read again every ``refresh_period_s``
  (:meth:`DashboardStore.refresh`), so a lost notification only delays the page.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Mapping, Sequence
from typing import Any, Final, Protocol

import asyncpg

import services.dashboard.scene as scene
from common.bus import Notification
from common.contract import keys, limits, people, zones
from common.contract.zones import Zone
from common.db import Database
from services.dashboard.fleet import Fleet
from services.dashboard.requests import GoalRequest, NewStrategy, Refused
from services.dashboard.timeline import Timeline, command_event, goal_event, strategy_event

Row = Mapping[str, Any]
logger = logging.getLogger("pnav.dashboard.store")

# the newest row of a robot-scoped table, for every robot
_NEWEST = """
SELECT t.* FROM robot r CROSS JOIN LATERAL (
    SELECT * FROM {table} WHERE robot_id = r.robot_id ORDER BY id DESC LIMIT 1) t
"""
NEWEST_TABLES: Final = (
    keys.ODOMETRY,
    keys.LASER_SCAN,
    keys.BATTERY,
    keys.GOAL,
    keys.PLANNED_PATH,
    keys.COMMAND2ROBOT,
)
# rows a provenance may name in a recommendation's `inputs` ({"laser_scan": 812, ...})
PROVENANCE_TABLES: Final = (
    keys.LASER_SCAN,
    keys.ODOMETRY,
    keys.BATTERY,
    keys.GOAL,
    keys.PLANNED_PATH,
)
DECISION_TABLES: Final = (keys.COMMAND2ROBOT, keys.SYSTEM_COMMAND)
# A row is read as the page can draw it, whatever it holds: JSON beyond migration 11's bounds
# comes as NULL with ``readable`` false (a row written before the bound, or by an owner,
# would otherwise fail the whole read: a parser's recursion, a number of 5 000 digits), and
# text is cut to what a page shows.
_STRATEGIES = f"""
SELECT s.code, left(s.planner_scenario, 64) AS planner_scenario,
       s.controller_scenarios[1:32] AS controller_scenarios,
       CASE WHEN b.readable THEN s.params END AS params, b.readable,
       left(s.description, {limits.MAX_STRATEGY_DESCRIPTION_CHARS}) AS description
FROM strategy s CROSS JOIN LATERAL (SELECT strategy_params_bounded(s.params) AS readable) b
ORDER BY s.code
"""
_RECOMMENDATIONS = f"""
SELECT id, robot_id, kind, source, priority, linear_mps, angular_rps, system_command, stamp,
       expires_stamp, reason, treated_by, created_at,
       CASE WHEN octet_length(inputs::text) <= {limits.MAX_PARAMS_BYTES}
                 AND jsonb_depth(inputs, {limits.MAX_PARAMS_DEPTH}) <= {limits.MAX_PARAMS_DEPTH}
            THEN inputs ELSE '{{"unreadable": "beyond the bounds of strategy params"}}' END
       AS inputs
FROM command_recommendation WHERE id = ANY($1::bigint[])
"""
_ROUTES = """
SELECT goal_id, seq, x, y, tolerance_m, yaw, yaw_tolerance_rad, stop, status,
       left(reason, 200) AS reason, reached_stamp
FROM goal_waypoint WHERE goal_id = ANY($1::bigint[]) ORDER BY goal_id, seq
"""
TIMELINE_TABLES: Final = (keys.GOAL, keys.USER_COMMAND, keys.SYSTEM_COMMAND)
_SEED_ROWS = 100


class DashboardSource(Protocol):
    async def robots(self) -> list[Row]: ...
    async def world(self) -> tuple[Row | None, list[Row]]: ...
    async def strategies(self) -> list[Row]: ...
    async def newest(self, table: str) -> list[Row]: ...
    async def active_strategies(self) -> list[Row]: ...
    async def row(self, table: str, row_id: int) -> Row | None: ...
    async def recent(self, table: str, robot: str | None, limit: int) -> list[Row]: ...
    async def recommendations(self, ids: Sequence[int]) -> list[Row]: ...
    async def set_goal(self, robot: str, goal: GoalRequest) -> int: ...
    async def routes(self, goal_ids: Sequence[int]) -> dict[int, list[Row]]: ...
    async def cancel_goal(self, robot: str) -> int | None: ...
    async def user_command(self, robot: str, command: str, argument: str | None) -> int: ...
    async def add_strategy(self, request: NewStrategy) -> None: ...
    async def zones(self) -> list[Zone]: ...
    async def add_zone(self, zone: Zone) -> None: ...
    async def remove_zone(self, name: str) -> bool: ...


class PgDashboardSource:
    """:class:`DashboardSource` on the contract's Postgres tables."""

    def __init__(self, db: Database) -> None:
        self.db = db

    async def robots(self) -> list[Row]:
        return list(await self.db.pool.fetch("SELECT * FROM robot ORDER BY robot_id"))

    async def world(self) -> tuple[Row | None, list[Row]]:
        pool = self.db.pool
        grid = await pool.fetchrow("SELECT * FROM map ORDER BY loaded_at DESC LIMIT 1")
        if grid is None:
            return None, []
        chargers = await pool.fetch(
            "SELECT * FROM charging_station WHERE map_id = $1 ORDER BY station_id", grid["map_id"]
        )
        return grid, list(chargers)

    async def strategies(self) -> list[Row]:
        return list(await self.db.pool.fetch(_STRATEGIES))

    async def newest(self, table: str) -> list[Row]:
        if table not in NEWEST_TABLES:
            raise Refused(404, f"no newest rows of {table!r}")
        return list(await self.db.pool.fetch(_NEWEST.format(table=table)))

    async def active_strategies(self) -> list[Row]:
        return list(await self.db.pool.fetch("SELECT * FROM active_strategy ORDER BY robot_id"))

    async def row(self, table: str, row_id: int) -> Row | None:
        if table not in (*TIMELINE_TABLES, *DECISION_TABLES, *PROVENANCE_TABLES):
            raise Refused(404, f"no rows of {table!r} here")
        row: Row | None = await self.db.pool.fetchrow(
            f"SELECT * FROM {table} WHERE id = $1", row_id
        )
        return row

    async def recent(self, table: str, robot: str | None, limit: int) -> list[Row]:
        """The newest ``limit`` rows of a timeline table (of ``robot``, or of every robot)."""
        if table not in TIMELINE_TABLES:
            raise Refused(404, f"no timeline of {table!r}")
        sql = (
            f"SELECT * FROM {table} WHERE $1::text IS NULL OR robot_id = $1 "
            "ORDER BY id DESC LIMIT $2"
        )
        return list(await self.db.pool.fetch(sql, robot, limit))

    async def recommendations(self, ids: Sequence[int]) -> list[Row]:
        return list(await self.db.pool.fetch(_RECOMMENDATIONS, list(ids)))

    async def set_goal(self, robot: str, goal: GoalRequest) -> int:
        return await people.set_route(self.db, robot, goal.pose, goal.waypoints)

    async def routes(self, goal_ids: Sequence[int]) -> dict[int, list[Row]]:
        """The waypoints of these goals (goal_waypoint), in seq order, per goal."""
        out: dict[int, list[Row]] = {}
        for row in await self.db.pool.fetch(_ROUTES, list(goal_ids)):
            out.setdefault(int(row["goal_id"]), []).append(row)
        return out

    async def cancel_goal(self, robot: str) -> int | None:
        return await people.cancel_goal(self.db, robot)

    async def user_command(self, robot: str, command: str, argument: str | None) -> int:
        return await people.user_command(self.db, robot, command, argument)

    async def zones(self) -> list[Zone]:
        return await zones.read_zones(self.db)

    async def add_zone(self, zone: Zone) -> None:
        try:
            await zones.add_zone(self.db, zone)
        except asyncpg.UniqueViolationError:
            raise Refused(409, f"name: a zone named {zone.name!r} exists already") from None

    async def remove_zone(self, name: str) -> bool:
        return await zones.remove_zone(self.db, name)

    async def add_strategy(self, request: NewStrategy) -> None:
        try:
            await self.db.write(
                keys.STRATEGY,
                None,
                "INSERT INTO strategy (code, planner_scenario, controller_scenarios, params, "
                "description) VALUES ($1, $2, $3, $4, $5)",
                request.code,
                request.planner_scenario,
                list(request.controller_scenarios),
                request.params,
                request.description,  # '' when none: the column is NOT NULL
            )
        except asyncpg.UniqueViolationError:
            raise Refused(409, f"strategy {request.code!r} exists already") from None


def _strategy(row: Row) -> dict[str, Any]:
    """A strategy as the page lists it; one it cannot draw is listed as unreadable, so the
    others still are."""
    try:
        return scene.strategy(row)
    except Exception as exc:
        logger.warning("strategy %r cannot be shown: %r", row.get("code"), exc)
        return {"code": str(row.get("code")), "unreadable": f"cannot be shown: {exc!r}"[:200]}


def _event(table: str, row: Row, *, seeded: bool = False) -> dict[str, Any] | None:
    """The timeline event of a goal or command row; None (logged) for one that cannot be
    drawn: one bad row must not stop the timeline."""
    try:
        return goal_event(row, seeded=seeded) if table == keys.GOAL else command_event(table, row)
    except Exception as exc:
        logger.warning("%s row %r cannot be shown: %r", table, row.get("id"), exc)
        return None


class DashboardStore:
    """What the page shows, kept up to date from notifications and the tables."""

    def __init__(self, source: DashboardSource) -> None:
        self.source = source
        self.fleet = Fleet()
        self.timeline = Timeline()
        self.world: dict[str, Any] = {"map": None, "chargers": [], "zones": []}
        self.strategies: list[dict[str, Any]] = []
        self.world_changed = self.strategies_changed = False
        # (table, robot) -> ids a notification named (None: the id was not given)
        self._dirty: dict[tuple[str, str | None], set[int | None]] = {}
        self.refreshed_at = 0.0
        self.loaded = asyncio.Event()

    # -- notifications -------------------------------------------------------------------
    def note(self, note: Notification) -> None:
        """A change notification, on the loop: use its image, or remember to read."""
        if note.robot is not None and self.fleet.apply(note):
            return
        if note.table in (keys.ROBOT, keys.MAP, keys.CHARGING_STATION, keys.STRATEGY, keys.ZONE):
            self._dirty.setdefault((note.table, None), set()).add(None)
        elif note.robot is not None and note.table in (
            keys.GOAL_WAYPOINT,
            *TIMELINE_TABLES,
            keys.ACTIVE_STRATEGY,
            *NEWEST_TABLES,
        ):
            self._dirty.setdefault((note.table, note.robot), set()).add(note.id)

    # -- reads ---------------------------------------------------------------------------
    async def refresh(self) -> None:
        """Read every table the page shows (at start, and every refresh period)."""
        source = self.source
        await self.read_globals()
        for table in NEWEST_TABLES:
            for row in await source.newest(table):
                self.fleet.set_row(table, row)
        for row in await source.active_strategies():
            self.fleet.set_row(keys.ACTIVE_STRATEGY, row)
        await self._read_routes(None)
        if not self.loaded.is_set():
            await self._seed_timeline()
        else:
            for row in await source.active_strategies():
                self.timeline.add(strategy_event(row))
        await self.fleet.resolve(source.recommendations)
        self.refreshed_at = time.monotonic()
        self.loaded.set()

    async def read_globals(self) -> None:
        source = self.source
        self.fleet.set_robots(await source.robots())
        grid, chargers = await source.world()
        world = {
            "map": scene.world_map(grid),
            "chargers": [scene.charger(c) for c in chargers],
            "zones": [z.image() for z in await source.zones()],
        }
        if world != self.world:
            self.world, self.world_changed = world, True
        strategies = [_strategy(r) for r in await source.strategies()]
        if strategies != self.strategies:
            self.strategies, self.strategies_changed = strategies, True

    async def _seed_timeline(self) -> None:
        events = []
        for table in TIMELINE_TABLES:
            for row in await self.source.recent(table, None, _SEED_ROWS):
                event = _event(table, row, seeded=True)
                if event is not None:
                    events.append(event)
        events += [strategy_event(row) for row in await self.source.active_strategies()]
        self.timeline.seed(events)

    async def flush(self) -> None:
        """Read what notifications marked (without an image), and the rows decisions name."""
        dirty, self._dirty = self._dirty, {}
        if any(robot is None for _table, robot in dirty):
            await self.read_globals()
        newest: dict[str, set[str]] = {}  # one query per table serves every robot
        routes = {r for (t, r) in dirty if t in (keys.GOAL, keys.GOAL_WAYPOINT) and r}
        for (table, robot), ids in dirty.items():
            if robot is None or table == keys.GOAL_WAYPOINT:
                continue
            if table in NEWEST_TABLES and table != keys.GOAL:
                newest.setdefault(table, set()).add(robot)
            else:
                await self._read(table, robot, ids)
        for table, robots in newest.items():
            for row in await self.source.newest(table):
                if row["robot_id"] in robots:
                    self.fleet.set_row(table, row)
        if routes:
            await self._read_routes(routes)
        await self.fleet.resolve(self.source.recommendations)

    async def _read_routes(self, robots: set[str] | None) -> None:
        """The waypoints of these robots' goals (None: every robot's), in one query."""
        goals = self.fleet.goal_ids(robots)
        if goals:
            found = await self.source.routes(list(goals.values()))
            for robot, goal_id in goals.items():
                self.fleet.set_route(robot, goal_id, found.get(goal_id, []))

    async def _read(self, table: str, robot: str, ids: set[int | None]) -> None:
        source = self.source
        if table == keys.ACTIVE_STRATEGY:
            for row in await source.active_strategies():
                if row["robot_id"] == robot:
                    self.fleet.set_row(table, row)
                    self.timeline.add(strategy_event(row))
            return
        if table in TIMELINE_TABLES:
            known = sorted(i for i in ids if i is not None)
            rows: list[Row | None]
            if known and None not in ids:
                rows = [await source.row(table, i) for i in known]
            else:
                rows = list(await source.recent(table, robot, 5))
            for found in rows:
                if found is None:
                    continue
                event = _event(table, found)
                if event is not None:
                    self.timeline.add(event)
                if table == keys.GOAL:
                    self.fleet.set_row(table, found)

    # -- what goes to the page -----------------------------------------------------------
    def snapshot(self) -> dict[str, Any]:
        return {
            "type": "snapshot",
            "world": self.world,
            "strategies": self.strategies,
            "robots": self.fleet.as_json(None),
            "timeline": self.timeline.events(),
        }

    def take_updates(self) -> list[dict[str, Any]]:
        """The messages for what changed since the last call (docs/DASHBOARD.md)."""
        messages: list[dict[str, Any]] = []
        if self.world_changed:
            self.world_changed = False
            messages.append({"type": "world", "world": self.world})
        if self.strategies_changed:
            self.strategies_changed = False
            messages.append({"type": "strategies", "strategies": self.strategies})
        changed = self.fleet.take_changed()
        if changed:
            messages.append({"type": "robots", "robots": self.fleet.as_json(changed)})
        fresh = self.timeline.take_fresh()
        if fresh:
            messages.append({"type": "timeline", "events": fresh})
        return messages

    def skip_updates(self) -> None:
        """Forget what changed (nobody is watching; a browser that comes gets a snapshot)."""
        self.world_changed = self.strategies_changed = False
        self.fleet.take_changed()
        self.timeline.take_fresh()

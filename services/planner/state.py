"""What the planner's rules share: the world as read from the contract, routes, rule slots.

The meta-planner refreshes this once per activation (the active strategies every time; the
robots, maps and charging stations only when a notification says they changed, or every
REFRESH_S as a fallback), so a target rule's own work is two or three small queries.

Service-specific SQL lives here; the common reads (odometry, goal, battery, strategies) come
from ``common.contract.records``.
"""

from __future__ import annotations

import logging
import math
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from common import log
from common.contract import keys, records
from common.db import Database
from services.planner.path import PlanGrid, path_length, plan_grid, plan_path, with_obstacles
from services.planner.tracking import Progress, Route, follow

logger = logging.getLogger("pnav.planner")

REFRESH_S = 2.0  # re-read robots, maps and stations at least this often (wall s)
# Re-read the active strategies, and each robot's active goal, when a notification says they
# changed, and at least this often (wall s) in case one was lost.
FAST_REFRESH_S = 0.5
INFLATION_MARGIN_M = 0.05  # clearance kept beyond the footprint radius when planning
STRAY_M = 0.4  # farther than this from the route: plan again from where the robot is
REPLAN_MIN_S = 0.5  # ...but not more often than this (wall s), so avoidance cannot thrash it
RETRY_PLAN_S = 2.0  # how long a straight-line fallback stands before A* is tried again
CHARGER_MARGIN_M = 0.1  # a charger is reached this far inside its radius
STATIONS_BY_PATH = 3  # nearest stations (straight line) whose path length is compared
# Unmapped obstacles, from the lidar (see ``PlannerState.see``):
SEEN_RANGE_M = 2.5  # lidar hits farther than this are not used (pose error grows with range)
UNMAPPED_M = 0.15  # a hit farther than this from every mapped obstacle is an unmapped one
SEEN_MAX_AGE_S = 1.0  # sim s: older obstacles are not planned around
POSE_MATCH_S = 0.05  # the scan's pose: odometry within this (sim s) of the scan's stamp
POSES_KEPT = 90  # odometry poses remembered per robot (3 s at 30 Hz)
BLOCKED_M = 0.3  # a new obstacle closer than this to the route ahead: plan again...
BLOCKED_RANGE_M = 2.0  # ...if it is within this of the robot
REPLAN_BLOCKED_S = 0.5  # ...at most this often (sim s)
OBSTACLE_BUCKET_M = 0.1  # obstacles within about this of one planned around are not new

_ROBOTS = "SELECT robot_id, world, max_linear_mps, max_angular_rps, footprint_radius_m FROM robot"
_MAP_VERSIONS = "SELECT map_id, loaded_at FROM map"
_MAP = (
    "SELECT resolution_m, origin_x, origin_y, origin_yaw, width, height, grid "
    "FROM map WHERE map_id = $1"
)
_STATIONS = "SELECT station_id, map_id, x, y, radius_m FROM charging_station ORDER BY station_id"
_MARK_REACHED = (
    "UPDATE goal SET status = 'reached', finished_stamp = $2 "
    "WHERE id = $1 AND status = 'active' RETURNING id"
)
_LIVE_SYSTEM = (
    "SELECT max(expires_stamp) FROM command_recommendation WHERE robot_id = $1 "
    "AND kind = 'system' AND system_command = $2 AND expires_stamp > $3"
)


@dataclass(frozen=True)
class RobotInfo:
    robot_id: str
    world: str | None
    max_linear_mps: float
    max_angular_rps: float
    footprint_radius_m: float


@dataclass(frozen=True)
class Station:
    station_id: str
    map_id: str | None
    x: float
    y: float
    radius_m: float


@dataclass(frozen=True)
class Target:
    """Where the robot is going: the active goal, or the chosen charging station."""

    kind: str  # "goal" or "charger"
    ref: str  # the goal id or the station id
    x: float
    y: float
    reach_m: float  # closer than this: reached
    hold_m: float  # once reached, stay stopped while closer than this
    goal_id: int | None = None

    @property
    def key(self) -> tuple[Any, ...]:
        return (self.kind, self.ref, self.x, self.y)

    @property
    def label(self) -> str:
        return f"{self.kind} {self.ref}"

    def inputs(self) -> dict[str, Any]:
        return {"goal": self.goal_id} if self.kind == "goal" else {"charger": self.ref}

    @classmethod
    def of_goal(cls, goal: records.Goal) -> Target:
        return cls("goal", str(goal.id), goal.x, goal.y, goal.tolerance_m, 0.0, goal.id)

    @classmethod
    def of_station(cls, station: Station) -> Target:
        reach = max(station.radius_m - CHARGER_MARGIN_M, station.radius_m / 2)
        return cls("charger", station.station_id, station.x, station.y, reach, station.radius_m)


class MapData:
    """One map row, with its planning grids per inflation radius (built on first use)."""

    def __init__(
        self,
        map_id: str,
        version: str,
        occupied: np.ndarray[Any, np.dtype[np.bool_]],
        resolution: float,
        origin: tuple[float, float, float],
    ) -> None:
        self.map_id = map_id
        self.version = version
        self.occupied = occupied
        self.resolution = resolution
        self.origin = origin
        self._grids: dict[float, PlanGrid] = {}

    def grid(self, footprint_m: float) -> PlanGrid:
        radius = round(footprint_m + INFLATION_MARGIN_M, 3)
        grid = self._grids.get(radius)
        if grid is None:
            grid = self._grids[radius] = plan_grid(
                self.occupied, self.resolution, self.origin, radius
            )
        return grid


@dataclass
class Slot:
    """The one live target rule of a kind ("move", "battery") for a robot."""

    spec: tuple[str, str]  # (rule class, strategy code)
    token: int
    beat: int  # meta round in which the rule last ran


@dataclass(frozen=True)
class Seen:
    """The unmapped obstacles of one laser scan: its hits farther than UNMAPPED_M from every
    obstacle of the map, in the world frame (an (n, 2) array)."""

    scan_id: int
    stamp: float
    points: np.ndarray[Any, np.dtype[np.float64]]


Pose = tuple[float, float, float, float]  # (stamp, x, y, yaw)


@dataclass(frozen=True)
class GoalRead:
    at: float  # wall time of the read
    mark: tuple[int, int]  # the goal notifications counted for the robot (and "*") by then
    goal: records.Goal | None


@dataclass
class RobotState:
    info: RobotInfo
    strategy: records.Strategy | None = None
    route: Route | None = None
    station: Station | None = None  # charger chosen for the current CHARGE session
    slots: dict[str, Slot] = field(default_factory=dict)
    poses: deque[Pose] = field(default_factory=lambda: deque(maxlen=POSES_KEPT))
    seen: Seen | None = None
    scan_read_at: float = -math.inf  # sim time the newest scan was last read
    goal_read: GoalRead | None = None  # the active goal, as last read

    def note_pose(self, odom: records.Odometry) -> None:
        if not self.poses or odom.stamp > self.poses[-1][0]:
            self.poses.append((odom.stamp, odom.x, odom.y, odom.yaw))
        elif odom.stamp < self.poses[-1][0] - 1.0:  # sim time went back: the sim restarted
            self.poses.clear()
            self.poses.append((odom.stamp, odom.x, odom.y, odom.yaw))

    def pose_at(self, stamp: float) -> tuple[float, float, float] | None:
        """The robot's pose at sim time ``stamp``, interpolated between the odometry rows
        around it; None if no row is within POSE_MATCH_S of it."""
        before = after = None
        for pose in reversed(self.poses):
            if pose[0] <= stamp:
                before = pose
                break
            after = pose
        if before is not None and after is not None and after[0] - before[0] <= 2 * POSE_MATCH_S:
            f = (stamp - before[0]) / max(after[0] - before[0], 1e-9)
            turn = math.atan2(math.sin(after[3] - before[3]), math.cos(after[3] - before[3]))
            return (
                before[1] + f * (after[1] - before[1]),
                before[2] + f * (after[2] - before[2]),
                before[3] + f * turn,
            )
        near = [p for p in (before, after) if p is not None and abs(p[0] - stamp) <= POSE_MATCH_S]
        if not near:
            return None
        best = min(near, key=lambda p: abs(p[0] - stamp))
        return best[1], best[2], best[3]


_NO_POINTS: np.ndarray[Any, np.dtype[np.float64]] = np.zeros((0, 2))


def _bucket(x: float, y: float) -> tuple[int, int]:
    return math.floor(x / OBSTACLE_BUCKET_M), math.floor(y / OBSTACLE_BUCKET_M)


def _buckets(points: np.ndarray[Any, np.dtype[np.float64]]) -> set[tuple[int, int]]:
    return {_bucket(float(px), float(py)) for px, py in points}


def _known(avoided: set[tuple[int, int]], x: float, y: float) -> bool:
    """Whether (x, y) is within a bucket of an obstacle the route was planned around."""
    bx, by = _bucket(x, y)
    return any((bx + i, by + j) in avoided for i in (-1, 0, 1) for j in (-1, 0, 1))


class PlannerState:
    def __init__(
        self,
        db: Database,
        now: Callable[[], float],
        started: Callable[[], bool],
        wall: Callable[[], float] = time.monotonic,
    ):
        self.db = db
        self.now = now  # sim time
        self.clock_started = started
        # The clock of the planner's own gates (re-reads, replanning, retries), in seconds:
        # wall time in the service; an in-process run may count them in sim time instead.
        self.wall = wall
        self.robots: dict[str, RobotState] = {}
        self.maps: dict[str, MapData] = {}
        self.stations: list[Station] = []
        self.meta_round = 0
        self.dirty = True  # robots, maps or stations changed (set from Zenoh's thread)
        self._refreshed = 0.0
        self.strategies_dirty = True  # active_strategy or strategy changed (Zenoh's thread)
        self._strategies_read = 0.0
        # Goal notifications per robot ("*": naming no robot), counted on Zenoh's thread.
        self.goal_notes: dict[str, int] = {}
        # odometry notifications per robot: a robot's rule evaluates on its own rows
        self.odometry_notes: dict[str, int] = {}
        self._warned: set[str] = set()

    # -- reading the world -------------------------------------------------------------------
    def note(self, key: str, payload: bytes) -> None:
        """Notification observer (Zenoh's thread): flag what changed, so the rules re-read
        robots, maps, stations, strategies and goals only then (or after a fallback time)."""
        try:
            table, robot = keys.parse_notify_key(key)
        except ValueError:
            return
        if table in (keys.ROBOT, keys.MAP, keys.CHARGING_STATION):
            self.dirty = True
        elif table in (keys.ACTIVE_STRATEGY, keys.STRATEGY):
            self.strategies_dirty = True
        elif table == keys.GOAL:
            who = robot or "*"
            self.goal_notes[who] = self.goal_notes.get(who, 0) + 1
        elif table == keys.ODOMETRY and robot is not None:
            self.odometry_notes[robot] = self.odometry_notes.get(robot, 0) + 1

    async def refresh(self) -> None:
        pool = self.db.pool
        now = self.wall()
        world = self.dirty or now - self._refreshed > REFRESH_S
        if world:
            self.dirty = False
            self._refreshed = now
            await self._refresh_world(pool)
        # The active strategies on every notification (a strategy switch acts at once), not on
        # every odometry row: those wake the planner 30 times a sim second.
        if world or self.strategies_dirty or now - self._strategies_read > FAST_REFRESH_S:
            self.strategies_dirty = False  # before the read: a later change flags it again
            self._strategies_read = now
            active = await records.active_strategies(pool)
            for robot_id, state in self.robots.items():
                entry = active.get(robot_id)
                state.strategy = entry.strategy if entry else None

    def _goal_mark(self, robot_id: str) -> tuple[int, int]:
        return self.goal_notes.get(robot_id, 0), self.goal_notes.get("*", 0)

    def goal_news(self, state: RobotState) -> bool:
        """Whether a goal notification for the robot came since its goal was last read."""
        cached = state.goal_read
        return cached is not None and cached.mark != self._goal_mark(state.info.robot_id)

    async def active_goal(self, state: RobotState) -> records.Goal | None:
        """The robot's active goal: read again after a goal notification for it, or
        FAST_REFRESH_S after the last read; otherwise the one read last (the planner is woken
        by every odometry row, and the goal hardly ever changes in between)."""
        robot_id = state.info.robot_id
        mark = self._goal_mark(robot_id)
        now = self.wall()
        cached = state.goal_read
        if cached is not None and cached.mark == mark and now - cached.at <= FAST_REFRESH_S:
            return cached.goal
        goal = await records.active_goal(self.db.pool, robot_id)
        state.goal_read = GoalRead(now, mark, goal)
        return goal

    async def _refresh_world(self, pool: Any) -> None:
        rows = await pool.fetch(_ROBOTS)
        seen = set()
        for row in rows:
            info = RobotInfo(**dict(row))
            seen.add(info.robot_id)
            state = self.robots.get(info.robot_id)
            if state is None:
                self.robots[info.robot_id] = RobotState(info)
            elif state.info != info:
                state.info = info
                state.route = None  # new footprint or world: plan again
        for gone in set(self.robots) - seen:
            del self.robots[gone]
        versions = {r["map_id"]: str(r["loaded_at"]) for r in await pool.fetch(_MAP_VERSIONS)}
        for map_id in set(self.maps) - set(versions):
            del self.maps[map_id]
        for map_id, version in versions.items():
            current = self.maps.get(map_id)
            if current is None or current.version != version:
                self.maps[map_id] = await self._load_map(pool, map_id, version)
        self.stations = [Station(**dict(r)) for r in await pool.fetch(_STATIONS)]

    async def _load_map(self, pool: Any, map_id: str, version: str) -> MapData:
        row = await pool.fetchrow(_MAP, map_id)
        cells = np.frombuffer(row["grid"], dtype=np.uint8).reshape(row["height"], row["width"])
        log.event(logger, logging.INFO, "map loaded", map=map_id, cells=int(cells.size))
        origin = (row["origin_x"], row["origin_y"], row["origin_yaw"])
        return MapData(map_id, version, cells >= 50, row["resolution_m"], origin)

    def map_for(self, info: RobotInfo) -> MapData | None:
        """The robot's world's map; the only map if the robot names none."""
        if info.world and info.world in self.maps:
            return self.maps[info.world]
        if len(self.maps) == 1:
            return next(iter(self.maps.values()))
        return None

    def warn_once(self, what: str, message: str, **fields: Any) -> None:
        if what not in self._warned:
            self._warned.add(what)
            log.event(logger, logging.WARNING, message, **fields)

    # -- routes ------------------------------------------------------------------------------
    def see(self, state: RobotState, scan: records.LaserScan) -> None:
        """Remember the unmapped obstacles of ``scan``: hits within SEEN_RANGE_M that are
        farther than UNMAPPED_M from every obstacle of the robot's map, placed in the world with
        the robot's pose at the scan's stamp. Nav2 calls this an obstacle layer: the route is
        then planned around a pallet or a crate the map does not show, rather than through it
        for the controllers to fight over."""
        data = self.map_for(state.info)
        pose = state.pose_at(scan.stamp)
        if data is None or pose is None:
            return
        x, y, yaw = pose
        ranges = np.asarray(scan.ranges, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            valid = (ranges >= scan.range_min - 1e-4) & (ranges <= SEEN_RANGE_M)
        angles = scan.angles()[valid] + yaw
        hits = np.column_stack(
            (x + ranges[valid] * np.cos(angles), y + ranges[valid] * np.sin(angles))
        )
        grid = data.grid(state.info.footprint_radius_m)
        if grid.clearance is not None and len(hits):
            cols, rows, inside = grid.cells_of(hits)  # hits off the map are dropped
            mapped = grid.clearance[rows[inside], cols[inside]] <= UNMAPPED_M
            hits = hits[inside][~mapped]
        state.seen = Seen(scan.id, scan.stamp, hits)

    def route_for(
        self, state: RobotState, x: float, y: float, target: Target, now: float | None = None
    ) -> Progress:
        """Progress along the robot's cached route to ``target``; plans (again) when the
        target or the map changed, the robot strayed, a straight fallback is due a retry, or
        a newly seen unmapped obstacle is close to the route ahead. ``now``: sim time."""
        data = self.map_for(state.info)
        version = data.version if data else None
        route = state.route
        wall = self.wall()
        if route is not None and route.target_key == target.key and route.map_version == version:
            progress = follow(route, x, y)
            age = wall - route.made_at
            retry = data is not None and not route.planned and age > RETRY_PLAN_S
            blocked = data is not None and self._blocked(state, route, x, y, now)
            if (
                not retry
                and not blocked
                and (progress.deviation_m <= STRAY_M or age < REPLAN_MIN_S)
            ):
                return progress
        obstacles = self._obstacles(state, now)
        points = self.plan(state, (x, y), (target.x, target.y), target.label, obstacles)
        if points is None and len(obstacles):
            # They close every way (or cover the goal): the map alone, and these obstacles
            # count as considered, so the next scans do not call for the same failed plan.
            points = self.plan(state, (x, y), (target.x, target.y), target.label)
        planned = points is not None
        if not planned and data is not None:
            self.warn_once(
                f"nopath-{state.info.robot_id}-{target.key}",
                "no path on the map; heading straight (retried every few seconds)",
                robot=state.info.robot_id,
                target=target.label,
            )
        state.route = Route.of(
            target.key, version, points or [(x, y), (target.x, target.y)], planned
        )
        state.route.made_at = self.wall()
        state.route.made_stamp = now if now is not None else 0.0
        state.route.avoided = _buckets(obstacles)
        state.route.checked_scan = state.seen.scan_id if state.seen is not None else None
        return follow(state.route, x, y)

    def _obstacles(
        self, state: RobotState, now: float | None
    ) -> np.ndarray[Any, np.dtype[np.float64]]:
        """The unmapped obstacles to plan around: the newest scan's, unless it is stale."""
        seen = state.seen
        if seen is None or (now is not None and now - seen.stamp > SEEN_MAX_AGE_S):
            return _NO_POINTS
        return seen.points

    def _blocked(
        self, state: RobotState, route: Route, x: float, y: float, now: float | None
    ) -> bool:
        """Whether a scan not yet checked against ``route`` shows an obstacle it was not
        planned around within BLOCKED_M of the route ahead (and BLOCKED_RANGE_M of the
        robot). At most one such replan every REPLAN_BLOCKED_S; a scan is checked once."""
        seen = state.seen
        if seen is None or seen.scan_id == route.checked_scan or now is None:
            return False
        if now - route.made_stamp < REPLAN_BLOCKED_S:
            return False  # checked again once the interval is over
        route.checked_scan = seen.scan_id
        points = self._obstacles(state, now)
        if not len(points):
            return False
        near = np.hypot(points[:, 0] - x, points[:, 1] - y) <= BLOCKED_RANGE_M
        points = points[near]
        if not len(points):
            return False
        close = points[route.clearance_ahead(x, y, points) < BLOCKED_M]
        return any(not _known(route.avoided, px, py) for px, py in close)

    def plan(
        self,
        state: RobotState,
        start: tuple[float, float],
        goal: tuple[float, float],
        what: str,
        obstacles: np.ndarray[Any, np.dtype[np.float64]] | None = None,
    ) -> list[tuple[float, float]] | None:
        """A* on the robot's map, around ``obstacles`` too if given (None: no map, or no path
        on it)."""
        data = self.map_for(state.info)
        if data is None:
            return None
        started = time.perf_counter()
        grid = data.grid(state.info.footprint_radius_m)
        if obstacles is not None and len(obstacles):
            grid = with_obstacles(grid, obstacles)
        points = plan_path(grid, start, goal)
        elapsed_ms = (time.perf_counter() - started) * 1000
        log.event(
            logger,
            logging.DEBUG,
            "path planned" if points else "no path",
            robot=state.info.robot_id,
            target=what,
            waypoints=len(points) - 1 if points else 0,
            length_m=round(path_length(points), 2) if points else None,
            unmapped=len(obstacles) if obstacles is not None else 0,
            ms=round(elapsed_ms, 1),
        )
        return points

    def distance(self, state: RobotState, a: tuple[float, float], b: tuple[float, float]) -> float:
        """Path length from a to b on the robot's map; straight line without one."""
        points = self.plan(state, a, b, "distance")
        return path_length(points) if points else math.hypot(b[0] - a[0], b[1] - a[1])

    def choose_station(self, state: RobotState, x: float, y: float) -> Station | None:
        """The nearest charger by path length (among the few nearest in a straight line),
        chosen once per CHARGE session so the target cannot flip while the robot drives."""
        if state.station is not None:
            return state.station
        data = self.map_for(state.info)
        here = [s for s in self.stations if data is None or s.map_id in (None, data.map_id)]
        if not here:
            here = list(self.stations)
        if not here:
            self.warn_once("no-station", "no charging station to go to", robot=state.info.robot_id)
            return None
        here.sort(key=lambda s: math.hypot(s.x - x, s.y - y))
        candidates = here[:STATIONS_BY_PATH] if data is not None else here[:1]
        state.station = min(candidates, key=lambda s: self.distance(state, (x, y), (s.x, s.y)))
        log.event(
            logger,
            logging.INFO,
            "charger chosen",
            robot=state.info.robot_id,
            station=state.station.station_id,
        )
        return state.station

    # -- writes ------------------------------------------------------------------------------
    async def mark_reached(self, goal_id: int, robot_id: str, stamp: float) -> bool:
        """Set the goal 'reached' (one statement) and notify; False if it was no longer active."""
        updated = await self.db.write(keys.GOAL, robot_id, _MARK_REACHED, goal_id, stamp)
        return updated is not None

    async def live_system(self, robot_id: str, command: str) -> float | None:
        """Expiry of this robot's newest unexpired ``command`` recommendation, if any."""
        value = await self.db.pool.fetchval(_LIVE_SYSTEM, robot_id, command, self.now())
        return float(value) if value is not None else None

    def forget(self, robot_ids: Iterable[str]) -> None:
        """Drop what is kept in memory about these robots (replicas: ownership changed)."""
        for robot_id in robot_ids:
            state = self.robots.get(robot_id)
            if state is not None:
                self.robots[robot_id] = RobotState(state.info, strategy=state.strategy)

    # -- rule slots --------------------------------------------------------------------------
    def claim(self, robot_id: str, kind: str, token: int) -> RobotState | None:
        """The robot's state if the rule holding ``token`` is still its ``kind`` rule; it
        records that the rule is alive (the meta-planner replaces a rule that stops beating)."""
        state = self.robots.get(robot_id)
        slot = state.slots.get(kind) if state else None
        if slot is None or slot.token != token:
            return None
        slot.beat = self.meta_round
        return state

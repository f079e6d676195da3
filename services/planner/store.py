"""Every read and write of the contract the planner does, and what notifications told it.

- :class:`~services.planner.source.PlannerSource` (services/planner/source.py): the raw
  typed reads and writes (a Protocol), and :class:`~services.planner.source.PgPlannerSource`,
  them in SQL on an asyncpg pool (the planner's only SQL);
- :class:`PlannerStore`: the one object the planner service holds. It takes a source and a
  clock, keeps the caches (the world, the active strategies, each robot's active goal, on
  ``common.freshness.FreshCache``), counts each robot's odometry notifications, and gives the
  rules the Protocols of view.py.

The caches are read again when a notification says their table changed, and at least every
REFRESH_S (the world: robots, maps, stations; the live scenario offers) or FAST_REFRESH_S
(strategies, goals, zones) of the store's clock in case one was lost. Goal rows change in place (a
status), so a goal notification always means "read it again", whatever id it names; the
planner hears every odometry row (30 Hz per robot) and reads neither the world nor the
strategies for those.

Row images (CONTRACT.md "Row images"): an odometry notification's image becomes the robot's
newest odometry without a query; the table is read instead when the newest notification had
no image or followed a ``seq`` gap, or none came for FAST_REFRESH_S (the period fallback).
A battery notification's image becomes the robot's newest battery row the same way, with
REFRESH_S as its period fallback (the battery is reported at 1 Hz: a shorter one would read
the table between every two reports).
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Awaitable, Callable, Iterable
from typing import Any, TypeVar, Unpack

import services.planner.chargers as chargers
from common import log
from common.bus import Notification
from common.contract import keys, records
from common.contract.offers import Offers
from common.contract.recommendations import (
    Recommendation,
    SystemFields,
    VelocityFields,
    recommendation_key,
)
from common.freshness import FreshCache
from common.images import GuardedStore, ImageGuard
from common.planner_core.scenario import RobotInfo
from common.writebehind import WriteBehind
from services.planner.published_path import PathRow
from services.planner.routes import Router, Target
from services.planner.source import PlannerSource
from services.planner.tracking import Progress
from services.planner.world_model import MapData, RobotState, Station, World, see

logger = logging.getLogger("pnav.planner")

R = TypeVar("R")

REFRESH_S = 2.0  # re-read robots, maps and stations at least this often (store clock)
# Re-read the active strategies, and each robot's active goal, when a notification says they
# changed, and at least this often (store clock) in case one was lost.
FAST_REFRESH_S = 0.5

_WORLD_TABLES = (keys.ROBOT, keys.MAP, keys.CHARGING_STATION)
_STRATEGY_TABLES = (keys.ACTIVE_STRATEGY, keys.STRATEGY)
# the keys of the whole-table caches
_WORLD, _ACTIVE, _OFFERS, _ZONES = "world", "active", "offers", "zones"


class PlannerStore(GuardedStore):
    """The planner's one view of the contract: caches, notifications, the world, routes."""

    def __init__(
        self,
        source: PlannerSource,
        clock: Callable[[], float],
        now: Callable[[], float],
        started: Callable[[], bool] = lambda: True,
    ) -> None:
        self.source = source
        self._clock = clock  # the planner's own gates: wall time, or sim time in lockstep
        self._now = now  # sim time
        self._started = started
        self.world = World()
        self.router = Router(self.world, clock)
        # FreshCache reads again once ``recheck_s`` has passed; the planner always read
        # again only once it was exceeded: the next float up keeps that to the last tick.
        self._world = FreshCache[str, None](clock, math.nextafter(REFRESH_S, math.inf))
        self._active = FreshCache[str, dict[str, records.ActiveStrategy]](
            clock, math.nextafter(FAST_REFRESH_S, math.inf)
        )
        self._goals = FreshCache[str, records.Goal | None](
            clock, math.nextafter(FAST_REFRESH_S, math.inf)
        )
        # the keepout and speed zones: read on their notification, and as often as the
        # strategies without one (people's rows, written by clients that may not notify)
        self._zones = FreshCache[str, None](clock, math.nextafter(FAST_REFRESH_S, math.inf))
        # what the live controllers offer (scenario_offer), read as often as the world
        self._offers = FreshCache[str, Offers](clock, math.nextafter(REFRESH_S, math.inf))
        self._routes_changed: set[str] = set()  # robots whose waypoints to read in full
        self._odometry_notes: dict[str, int] = {}
        # per robot: the newest odometry image and the store clock when it came (None: the
        # newest notification could not stand in for the table)
        self._odometry: dict[str, tuple[records.Odometry, float] | None] = {}
        self._battery: dict[str, tuple[records.Battery, float] | None] = {}  # the same
        # images held to their table's rules before they stand in for a query
        self.images = ImageGuard(logger)
        # velocity recommendations held until the activation ends (defer_recommendations);
        # None: each written when a rule asks
        self.outbox: WriteBehind[Recommendation] | None = None
        # per table: rows read from it because no image could stand in (tests, benchmarks)
        self.reads: Counter[str] = Counter()

    # -- clocks ------------------------------------------------------------------------------
    def now(self) -> float:
        return self._now()

    def started(self) -> bool:
        return self._started()

    def clock(self) -> float:
        return self._clock()

    # -- notifications -----------------------------------------------------------------------
    def note(self, note: Notification) -> None:
        """A change notification (on the loop): flag what changed, so the rules read robots,
        maps, stations, strategies and goals again only then (or after a fallback time)."""
        if note.table in _WORLD_TABLES:
            self._world.announce(_WORLD)
        elif note.table in _STRATEGY_TABLES:
            self._active.announce(_ACTIVE)
        elif note.table == keys.SCENARIO_OFFER:
            self._offers.announce(_OFFERS)
        elif note.table == keys.ZONE:
            self._zones.announce(_ZONES)
        elif note.table in (keys.GOAL, keys.GOAL_WAYPOINT):
            # a route's rows come with their goal (or after it, notified on their own): read
            # both again; a waypoint notification reads every waypoint, not only the count
            if note.robot is None:
                self._goals.announce_all()
                self._routes_changed.update(self.world.robots)
            else:
                self._goals.announce(note.robot)
                if note.table == keys.GOAL_WAYPOINT:
                    self._routes_changed.add(note.robot)
        elif note.table == keys.ODOMETRY and note.robot is not None:
            self._odometry_notes[note.robot] = self._odometry_notes.get(note.robot, 0) + 1
            self._image(self._odometry, records.odometry_of, note.robot, note)
        elif note.table == keys.BATTERY and note.robot is not None:
            self._image(self._battery, records.battery_of, note.robot, note)

    def _image(
        self,
        held: dict[str, Any],
        parse: Callable[[Any], Any],
        robot_id: str,
        note: Notification,
    ) -> None:
        """Keep ``note``'s image as the robot's newest row of its table in ``held`` (with the
        store clock when it came), or None when it cannot stand in for the table."""
        # a lost notification before it, no image, or one the table's rules refuse (or that
        # does not parse): read the table
        row = self.images.fresh(note, parse)
        if row is None:
            held[robot_id] = None
            return
        newest = held.get(robot_id)
        if newest is None or row.id > newest[0].id:
            held[robot_id] = (row, self._clock())

    def forget(self, robot_ids: Iterable[str]) -> None:
        """Drop what is kept in memory about these robots (replicas: ownership changed)."""
        for robot_id in robot_ids:
            self.world.forget(robot_id)
            self._goals.forget(robot_id)
            self._odometry.pop(robot_id, None)
            self._battery.pop(robot_id, None)

    # -- the meta-planner's view -------------------------------------------------------------
    async def refresh(self) -> None:
        """The world when it changed; the active strategies on every notification of theirs
        (a strategy switch acts at once), not on every odometry row."""
        if self._world.stale(_WORLD):
            await self._world.get(_WORLD, self._read_world)
            self._active.announce(_ACTIVE)  # with the robots just read
        if self._active.stale(_ACTIVE):
            active = await self._active.get(_ACTIVE, self.source.active_strategies)
            for robot_id, state in self.world.robots.items():
                entry = active.get(robot_id)
                state.strategy = entry.strategy if entry else None

        if self._offers.stale(_OFFERS):
            await self._offers.get(_OFFERS, self.source.live_offers)
        if self._zones.stale(_ZONES):
            await self._zones.get(_ZONES, self._read_zones)

    def offers(self) -> Offers:
        """The live planners' and controllers' offers, as last read (none before)."""
        return self._offers.peek(_OFFERS) or Offers()

    async def _read_world(self) -> None:
        world = self.world
        for robot_id in world.set_robots(await self.source.robots()):
            self._goals.forget(robot_id)  # a robot that comes back reads its goal afresh
        for map_id in world.stale_maps(versions := await self.source.map_versions()):
            row = await self.source.map(map_id, versions[map_id])
            if row is not None:
                world.maps[map_id] = MapData.of_row(row)
        world.stations = await self.source.stations()

    async def _read_zones(self) -> None:
        zones = tuple(await self.source.zones())
        if zones != self.world.zones:
            # the routes made on the old ones go stale by themselves (routes.py)
            keepouts = sum(1 for z in zones if z.keepout)
            log.event(logger, logging.INFO, "zones read", keepout=keepouts, total=len(zones))
        self.world.set_zones(zones)

    def robots(self) -> Iterable[RobotState]:
        return self.world.robots.values()

    def warn_once(self, what: str, message: str, **fields: Any) -> None:
        self.world.warn_once(what, message, **fields)

    # -- the target rules' view: reads -------------------------------------------------------
    def odometry_notes(self, robot_id: str) -> int:
        return self._odometry_notes.get(robot_id, 0)

    def goal_news(self, robot: RobotState) -> bool:
        return self._goals.hinted(robot.info.robot_id)

    async def active_goal(self, robot: RobotState) -> records.Goal | None:
        robot_id = robot.info.robot_id
        known = None if robot_id in self._routes_changed else self._goals.peek(robot_id)
        if self._goals.stale(robot_id):
            self._routes_changed.discard(robot_id)
        return await self._goals.get(robot_id, lambda: self.source.active_goal(robot_id, known))

    async def _newest(
        self,
        table: str,
        images: dict[str, tuple[R, float] | None],
        robot_id: str,
        max_age_s: float,
        read: Callable[[str], Awaitable[R | None]],
    ) -> R | None:
        """The robot's newest row of ``table``: as its notification carried it, while that
        is younger than ``max_age_s`` (wall or lockstep s); else ``read`` from the source
        (counted in :attr:`reads`)."""
        image = images.get(robot_id)
        if image is not None and self._clock() - image[1] < max_age_s:
            return image[0]
        self.reads[table] += 1
        return await read(robot_id)

    async def newest_odometry(self, robot_id: str) -> records.Odometry | None:
        return await self._newest(
            keys.ODOMETRY, self._odometry, robot_id, FAST_REFRESH_S, self.source.newest_odometry
        )

    async def newest_scan(self, robot_id: str) -> records.LaserScan | None:
        return await self.source.newest_scan(robot_id)

    async def newest_battery(self, robot_id: str) -> records.Battery | None:
        return await self._newest(
            keys.BATTERY, self._battery, robot_id, REFRESH_S, self.source.newest_battery
        )

    @property
    def odometry_reads(self) -> int:
        """Odometry read from the table (tests, benchmarks)."""
        return self.reads[keys.ODOMETRY]

    @property
    def battery_reads(self) -> int:
        """Battery rows read from the table (tests, benchmarks)."""
        return self.reads[keys.BATTERY]

    # -- writes ------------------------------------------------------------------------------
    async def mark_reached(self, goal_id: int, robot_id: str, stamp: float) -> bool:
        return await self.source.mark_reached(goal_id, robot_id, stamp)

    async def mark_failed(
        self, goal_id: int, robot_id: str, reason: str, stamp: float, strategy: str | None = None
    ) -> bool:
        return await self.source.mark_failed(goal_id, robot_id, reason, stamp, strategy)

    async def mark_waypoint(
        self, goal_id: int, seq: int, robot_id: str, status: str, reason: str | None, stamp: float
    ) -> bool:
        return await self.source.mark_waypoint(goal_id, seq, robot_id, status, reason, stamp)

    async def live_system(self, robot_id: str, command: str) -> float | None:
        return await self.source.live_system(robot_id, command, self.now())

    async def recommend_velocity(self, robot_id: str, **row: Unpack[VelocityFields]) -> None:
        rec = Recommendation.velocity(robot_id, **row)
        if self.outbox is not None:
            self.outbox.add(rec)
            return
        await self.source.recommend(rec)

    def defer_recommendations(self) -> Callable[[], Awaitable[None]]:
        """Hold every velocity recommendation until the returned hook is awaited, then
        write them in one statement (``Engine.at_activation_end``: common.writebehind).
        Without it each is written when its rule asks. System recommendations are always
        written at once: the battery rule reads them back (``live_system``) before writing."""
        if self.outbox is None:
            self.outbox = WriteBehind(
                self.source.recommend_many, recommendation_key, "command_recommendation"
            )
        return self.outbox.flush

    async def recommend_system(self, robot_id: str, **row: Unpack[SystemFields]) -> int:
        rec = Recommendation.system(robot_id, **row)
        return await self.source.recommend(rec)

    async def publish_path(self, path: PathRow) -> int:
        return await self.source.publish_path(path)

    # -- the world and routes ----------------------------------------------------------------
    def robot(self, robot_id: str) -> RobotState | None:
        return self.world.robots.get(robot_id)

    def map_for(self, info: RobotInfo) -> MapData | None:
        return self.world.map_for(info)

    def see(self, robot: RobotState, scan: records.LaserScan) -> None:
        see(self.world, robot, scan)

    def route_for(
        self, robot: RobotState, x: float, y: float, target: Target, now: float | None = None
    ) -> Progress:
        return self.router.route_for(robot, x, y, target, now)

    def distance(self, robot: RobotState, a: tuple[float, float], b: tuple[float, float]) -> float:
        return self.router.distance(robot, a, b)

    def choose_station(self, robot: RobotState, x: float, y: float) -> Station | None:
        return chargers.choose_station(self.world, self.router, robot, x, y)

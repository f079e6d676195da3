"""The world as the planner knows it: robots, maps with their planning grids, charging stations.

The store (store.py) fills it from the contract (robot, map and charging_station rows) when
a notification says they changed, or every REFRESH_S as a fallback; the rules read it. Per
robot it also holds what the planner works out between two activations: the strategy, the
cached route, the charger of a CHARGE session, the poses and the obstacles seen.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from common import log
from common.contract import records
from common.contract.zones import Zone
from common.planner_core.scenario import RobotInfo
from services.planner.grid import OCCUPIED_AT, PlanGrid, plan_grid
from services.planner.keepout import Keepouts, with_keepouts, zones_key
from services.planner.obstacles import (
    MAX_REMEMBERED,
    SEEN_RANGE_M,
    SURFACE_PUSH_CELLS,
    UNMAPPED_M,
    PoseTrail,
    Seen,
    one_per_cell,
    remembered,
)
from services.planner.tracking import Route

logger = logging.getLogger("pnav.planner")

INFLATION_MARGIN_M = 0.05  # clearance kept beyond the footprint radius when planning
# planning grids kept per map (footprints x keepout sets); older ones are dropped when the
# zones change, so a map's grids never pile up however often people edit zones
GRIDS_KEPT = 8


def inflation_m(footprint_m: float) -> float:
    """The planning grid's blocked radius around obstacles for a robot's footprint."""
    return round(footprint_m + INFLATION_MARGIN_M, 3)


@dataclass(frozen=True)
class Station:
    station_id: str
    map_id: str | None
    x: float
    y: float
    radius_m: float


@dataclass(frozen=True)
class MapRow:
    """One row of the map table, as the source reads it (cells: height x width, row 0 at the
    bottom)."""

    map_id: str
    version: str
    cells: np.ndarray[Any, np.dtype[np.uint8]]
    resolution: float
    origin: tuple[float, float, float]

    @classmethod
    def of(cls, map_id: str, version: str, row: Mapping[str, Any]) -> MapRow:
        """Map ``map_id``'s row (its grid bytes, height x width) as the planner keeps it."""
        cells = np.frombuffer(row["grid"], dtype=np.uint8).reshape(row["height"], row["width"])
        origin = (row["origin_x"], row["origin_y"], row["origin_yaw"])
        return cls(map_id, version, cells, row["resolution_m"], origin)


@dataclass(eq=False)
class MapData:
    """One map row, with its planning grids per inflation radius (built on first use)."""

    map_id: str
    version: str
    occupied: np.ndarray[Any, np.dtype[np.bool_]] = field(repr=False)
    resolution: float
    origin: tuple[float, float, float]
    _grids: dict[tuple[float, str], PlanGrid] = field(default_factory=dict, init=False, repr=False)
    _occupied: dict[str, np.ndarray[Any, np.dtype[np.bool_]]] = field(
        default_factory=dict, init=False, repr=False
    )

    @classmethod
    def of_row(cls, row: MapRow) -> MapData:
        log.event(logger, logging.INFO, "map loaded", map=row.map_id, cells=int(row.cells.size))
        return cls(row.map_id, row.version, row.cells >= OCCUPIED_AT, row.resolution, row.origin)

    def occupied_with(self, keepouts: tuple[Zone, ...] = ()) -> np.ndarray[Any, np.dtype[np.bool_]]:
        """The map's obstacles with the cells of ``keepouts`` (keepout zones) added."""
        if not keepouts:
            return self.occupied
        key = zones_key(keepouts)
        occupied = self._occupied.get(key)
        if occupied is None:
            if len(self._occupied) >= GRIDS_KEPT:
                self._occupied.clear()
            occupied = with_keepouts(self.occupied, keepouts, self.resolution, self.origin)
            self._occupied[key] = occupied
        return occupied

    def grid(self, footprint_m: float, keepouts: tuple[Zone, ...] = ()) -> PlanGrid:
        """The planning grid for a footprint, with ``keepouts`` (keepout zones) as obstacles."""
        radius = inflation_m(footprint_m)
        key = (radius, zones_key(keepouts) if keepouts else "")
        grid = self._grids.get(key)
        if grid is None:
            if len(self._grids) >= GRIDS_KEPT:
                self._grids.clear()
            grid = self._grids[key] = plan_grid(
                self.occupied_with(keepouts), self.resolution, self.origin, radius
            )
        return grid


@dataclass
class RobotState:
    info: RobotInfo
    strategy: records.Strategy | None = None
    route: Route | None = None
    station: Station | None = None  # charger chosen for the current CHARGE session
    poses: PoseTrail = field(default_factory=PoseTrail)
    seen: Seen | None = None
    scan_read_at: float = -math.inf  # sim time the newest scan was last read
    # the goal spot last judged (target key, map version) and why it cannot be reached
    spot: tuple[tuple[Any, ...], str | None] | None = None

    def note_pose(self, odom: records.Odometry) -> None:
        self.poses.note(odom)

    def pose_at(self, stamp: float) -> tuple[float, float, float] | None:
        return self.poses.at(stamp)


class World:
    """Robots by id (in the order the contract lists them), maps by id, stations."""

    def __init__(self) -> None:
        self.robots: dict[str, RobotState] = {}
        self.maps: dict[str, MapData] = {}
        self.stations: list[Station] = []
        self.zones: tuple[Zone, ...] = ()  # every zone row, by name
        self._keepouts: dict[str, Keepouts] = {}  # per robot, for the zones above
        self._warned: set[str] = set()

    def set_robots(self, infos: Iterable[RobotInfo]) -> set[str]:
        """Take the robot rows as read; the ids of the robots that came or went."""
        seen: set[str] = set()
        changed: set[str] = set()
        for info in infos:
            seen.add(info.robot_id)
            state = self.robots.get(info.robot_id)
            if state is None:
                self.robots[info.robot_id] = RobotState(info)
                changed.add(info.robot_id)
            elif state.info != info:
                state.info = info
                state.route = None  # new footprint or world: plan again
        for gone in set(self.robots) - seen:
            del self.robots[gone]
            changed.add(gone)
        return changed

    def stale_maps(self, versions: dict[str, str]) -> list[str]:
        """Drop the maps no longer in ``versions``; the ids of those to (re)load, in order."""
        for map_id in set(self.maps) - set(versions):
            del self.maps[map_id]
        return [
            map_id
            for map_id, version in versions.items()
            if map_id not in self.maps or self.maps[map_id].version != version
        ]

    def map_for(self, info: RobotInfo) -> MapData | None:
        """The robot's world's map; the only map if the robot names none."""
        if info.world and info.world in self.maps:
            return self.maps[info.world]
        if len(self.maps) == 1:
            return next(iter(self.maps.values()))
        return None

    def set_zones(self, zones: tuple[Zone, ...]) -> None:
        if zones != self.zones:
            self.zones = zones
            self._keepouts.clear()

    def keepouts(self, info: RobotInfo) -> Keepouts:
        """The keepout zones that apply to the robot, by name (worked out once per zone set:
        the rules ask on every activation)."""
        held = self._keepouts.get(info.robot_id)
        if held is None:
            robot = info.robot_id
            held = self._keepouts[robot] = Keepouts(z for z in self.zones if z.applies_to(robot))
        return held

    def forget(self, robot_id: str) -> None:
        """Start the robot afresh (its strategy stays: it is the contract's, read as usual)."""
        state = self.robots.get(robot_id)
        if state is not None:
            self.robots[robot_id] = RobotState(state.info, strategy=state.strategy)

    def warn_once(self, what: str, message: str, **fields: Any) -> None:
        if what not in self._warned:
            self._warned.add(what)
            log.event(logger, logging.WARNING, message, **fields)


def see(world: World, state: RobotState, scan: records.LaserScan) -> None:
    """Remember the unmapped obstacles of ``scan`` on ``state.seen``: hits within
    SEEN_RANGE_M that are farther than UNMAPPED_M from every obstacle of the robot's map,
    placed in the world with the robot's pose at the scan's stamp (nothing changes when
    there is no map or no pose for that stamp)."""
    data = world.map_for(state.info)
    pose = state.poses.at(scan.stamp)
    if data is None or pose is None:
        return
    x, y, yaw = pose
    ranges = np.asarray(scan.ranges, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        valid = (ranges >= scan.range_min - 1e-4) & (ranges <= SEEN_RANGE_M)
    angles = scan.angles()[valid] + yaw
    grid = data.grid(state.info.footprint.inscribed_m)
    reach = ranges[valid] + SURFACE_PUSH_CELLS * grid.resolution
    hits = np.column_stack((x + reach * np.cos(angles), y + reach * np.sin(angles)))
    if grid.clearance is not None and len(hits):
        cols, rows, inside = grid.cells_of(hits)  # hits off the map are dropped
        mapped = grid.clearance[rows[inside], cols[inside]] <= UNMAPPED_M
        hits = hits[inside][~mapped]
    hits = one_per_cell(hits, grid.resolution)
    kept, kept_at = remembered(state.seen, scan, (x, y, yaw), hits)
    points = np.concatenate((hits, kept)) if len(kept) else hits
    seen_at = np.concatenate((np.full(len(hits), scan.stamp), kept_at))
    state.seen = Seen(scan.id, scan.stamp, points[:MAX_REMEMBERED], seen_at[:MAX_REMEMBERED])

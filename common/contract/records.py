"""Typed rows of the contract tables, and the queries every scenario service needs.

Services may write their own SQL against CONTRACT.md; these are the common reads and writes
so that four services do not each re-implement "the newest odometry of robot r". All take an
asyncpg connection (or pool) and return plain frozen dataclasses.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, fields, replace
from typing import Any, Final, TypeAlias, TypeVar

import asyncpg
import numpy as np

from common.contract import keys, tables
from common.contract.columns import BOOL, FLOAT, FLOATS, ID, INT, Column, Table
from common.footprint import Footprinted, Polygon
from common.robotmodel import DEFAULT_MODEL, load_model
from common.scan import beam_angles, readings

# the robot table's defaults for the model columns are the default model's (schema.sql)
_DEFAULT_MODEL = load_model(DEFAULT_MODEL)

# A connection or a pool: both have fetch/fetchrow/fetchval.
Executor: TypeAlias = Any
_R = TypeVar("_R")


@dataclass(frozen=True)
class Robot(Footprinted):
    robot_id: str
    max_linear_mps: float
    max_angular_rps: float
    footprint_radius_m: float
    battery_capacity_wh: float
    # the hardest the robot speeds up and brakes (its model's; stopping distances use them)
    max_linear_accel_mps2: float = _DEFAULT_MODEL.max_linear_accel_mps2
    max_angular_accel_rps2: float = _DEFAULT_MODEL.max_angular_accel_rps2
    # the row's footprint_polygon (robot frame, counter-clockwise); None: the disc of
    # footprint_radius_m. Read it through ``footprint``.
    footprint_polygon: Polygon | None = None

    def braking_m(self, speed_mps: float) -> float:
        """Distance the robot needs to stop from ``speed_mps`` at its acceleration limit."""
        return speed_mps * speed_mps / (2.0 * self.max_linear_accel_mps2)


@dataclass(frozen=True)
class Odometry:
    id: int
    robot_id: str
    stamp: float
    x: float
    y: float
    yaw: float
    linear_mps: float
    angular_rps: float


@dataclass(frozen=True)
class LaserScan:
    id: int
    robot_id: str
    stamp: float
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: np.ndarray[Any, np.dtype[np.float32]]

    def angles(self) -> np.ndarray[Any, np.dtype[np.float64]]:
        """Beam angles relative to the heading, wrapped to (-pi, pi] (read-only: shared by
        every scan with the same geometry)."""
        return beam_angles(self.angle_min, self.angle_increment, len(self.ranges))

    def sector_min(self, low: float, high: float) -> float:
        """Closest valid range among beams with angle in [low, high] (rad); inf if none."""
        angles = self.angles()
        mask = (angles >= low) & (angles <= high) & readings(self.ranges, self.range_min)
        return float(self.ranges[mask].min()) if mask.any() else math.inf


@dataclass(frozen=True)
class Battery:
    id: int
    robot_id: str
    stamp: float
    energy_wh: float
    capacity_wh: float
    percentage: float
    charging: bool


@dataclass(frozen=True)
class Strategy:
    code: str
    planner_scenario: str | None
    controller_scenarios: tuple[str, ...]
    params: dict[str, Any]


@dataclass(frozen=True)
class ActiveStrategy:
    robot_id: str
    strategy: Strategy
    resume_code: str | None
    source: str


@dataclass(frozen=True)
class Waypoint:
    """A goal_waypoint row (migration 13): one pose of a route, and the planner's progress."""

    seq: int
    x: float
    y: float
    tolerance_m: float
    yaw: float | None = None
    yaw_tolerance_rad: float | None = None
    stop: bool = False
    status: str = "pending"


@dataclass(frozen=True)
class Goal:
    id: int
    robot_id: str
    x: float
    y: float
    tolerance_m: float
    # the heading to stop at (rad, map frame) and within what (NULL with a yaw: 0.1 rad)
    yaw: float | None = None
    yaw_tolerance_rad: float | None = None
    # the route's waypoints before the goal's own pose, in seq order
    waypoints: tuple[Waypoint, ...] = ()
    # how many goal_waypoint rows the goal had when read (the waypoints are read again when
    # this changes: a row added after the goal's notification)
    waypoint_count: int = 0


@dataclass(frozen=True)
class ChargingStation:
    station_id: str
    x: float
    y: float
    radius_m: float


async def robots(db: Executor) -> list[Robot]:
    rows = await db.fetch(
        "SELECT robot_id, max_linear_mps, max_angular_rps, footprint_radius_m, "
        "battery_capacity_wh, max_linear_accel_mps2, max_angular_accel_rps2, footprint_polygon "
        "FROM robot ORDER BY robot_id"
    )
    return [
        Robot(**{**dict(r), "footprint_polygon": polygon_of(r["footprint_polygon"])}) for r in rows
    ]


def polygon_of(value: Any) -> Polygon | None:
    """A robot row's ``footprint_polygon`` (an array of [x, y] rows, or NULL) as a tuple."""
    if value is None:
        return None
    return tuple((float(x), float(y)) for x, y in value)


async def _newest(db: Executor, table: str, record: type, robot_id: str) -> asyncpg.Record | None:
    """A robot's newest row of a sensor ``table`` (the columns of its ``record``), or None."""
    columns = ", ".join(f.name for f in fields(record))
    return await db.fetchrow(
        f"SELECT {columns} FROM {table} WHERE robot_id = $1 ORDER BY id DESC LIMIT 1", robot_id
    )


async def newest_odometry(db: Executor, robot_id: str) -> Odometry | None:
    row = await _newest(db, keys.ODOMETRY, Odometry, robot_id)
    return Odometry(**dict(row)) if row else None


# LATERAL + LIMIT 1 walks the (robot_id, id DESC) index once per robot asked for
_NEWEST_ODOMETRIES = """
SELECT o.id, o.robot_id, o.stamp, o.x, o.y, o.yaw, o.linear_mps, o.angular_rps
FROM unnest($1::text[]) AS r(robot_id)
CROSS JOIN LATERAL (
    SELECT id, robot_id, stamp, x, y, yaw, linear_mps, angular_rps FROM odometry
    WHERE odometry.robot_id = r.robot_id ORDER BY id DESC LIMIT 1
) o
"""


async def newest_odometries(db: Executor, robot_ids: Sequence[str]) -> dict[str, Odometry | None]:
    """Each robot's newest odometry (None: none yet), in one round trip."""
    rows = await db.fetch(_NEWEST_ODOMETRIES, list(robot_ids))
    found: dict[str, Odometry | None] = dict.fromkeys(robot_ids)
    for row in rows:
        found[row["robot_id"]] = Odometry(**dict(row))
    return found


async def newest_scan(db: Executor, robot_id: str) -> LaserScan | None:
    row = await _newest(db, keys.LASER_SCAN, LaserScan, robot_id)
    return None if row is None else _laser_scan(row)


def _laser_scan(row: asyncpg.Record) -> LaserScan:
    return LaserScan(
        id=row["id"],
        robot_id=row["robot_id"],
        stamp=row["stamp"],
        angle_min=row["angle_min"],
        angle_increment=row["angle_increment"],
        range_min=row["range_min"],
        range_max=row["range_max"],
        ranges=np.asarray(row["ranges"], dtype=np.float32),
    )


_SCAN_AND_ODOMETRY = (
    "SELECT s.id, s.robot_id, s.stamp, s.angle_min, s.angle_increment, s.range_min, "
    "s.range_max, s.ranges, o.id AS o_id, o.stamp AS o_stamp, o.x AS o_x, o.y AS o_y, "
    "o.yaw AS o_yaw, o.linear_mps AS o_linear_mps, o.angular_rps AS o_angular_rps "
    "FROM (SELECT * FROM laser_scan WHERE robot_id = $1 ORDER BY id DESC LIMIT 1) s "
    "LEFT JOIN LATERAL (SELECT * FROM odometry WHERE robot_id = $1 ORDER BY id DESC LIMIT 1) o "
    "ON true"
)


async def newest_scan_and_odometry(
    db: Executor, robot_id: str
) -> tuple[LaserScan | None, Odometry | None]:
    """The robot's newest scan and newest odometry in one round trip (odometry is None
    when there is no scan yet, or no odometry)."""
    row = await db.fetchrow(_SCAN_AND_ODOMETRY, robot_id)
    if row is None:
        return None, None
    scan = _laser_scan(row)
    if row["o_id"] is None:
        return scan, None
    # the odometry columns come prefixed "o_", as newest_odometry reads them unprefixed
    odom = Odometry(robot_id=robot_id, **{k[2:]: v for k, v in row.items() if k[:2] == "o_"})
    return scan, odom


# -- records from row images (CONTRACT.md "Row images"): the same record the query gives ----
def _floats(column: Column) -> Callable[[Any], Any]:
    dtype = np.float32 if column.sql_type == "real[]" else np.float64

    def convert(value: Any) -> Any:
        # an array column: a list of floats (``inf`` kept), or the packed bytes of one
        if isinstance(value, bytes | bytearray | memoryview):
            return np.frombuffer(value, dtype=dtype)
        return np.asarray(value, dtype=dtype)

    return convert


_CONVERT: dict[str, Callable[[Any], Any]] = {ID: int, INT: int, FLOAT: float, BOOL: bool}


def _parser(cls: type[_R], table: Table) -> Callable[[Mapping[str, Any]], _R]:
    """How an image of ``table`` becomes a ``cls``: each of its fields from the column of
    its name, as the column's declared type says (a bool column left out is false)."""
    converts: list[tuple[str, Callable[[Any], Any] | None, bool]] = []
    for name in (f.name for f in fields(cls)):  # type: ignore[arg-type]
        column = table.column(name)
        convert = _floats(column) if column.type == FLOATS else _CONVERT.get(column.type)
        converts.append((name, convert, column.type == BOOL))

    def parse(image: Mapping[str, Any]) -> _R:
        values = {
            name: (image.get(name, False) if optional else image[name])
            for name, _, optional in converts
        }
        for name, convert, _ in converts:
            if convert is not None:
                values[name] = convert(values[name])
        return cls(**values)

    return parse


odometry_of: Final = _parser(Odometry, tables.ODOMETRY)
odometry_of.__doc__ = "The :class:`Odometry` of an odometry row's image (as the query reads it)."
laser_scan_of: Final = _parser(LaserScan, tables.LASER_SCAN)
laser_scan_of.__doc__ = """The :class:`LaserScan` of a laser_scan row's image. ``ranges`` is the
real[] column: a list of floats (``inf`` kept), or the float32 bytes of one (a writer may pack
it)."""
battery_of: Final = _parser(Battery, tables.BATTERY)
battery_of.__doc__ = "The :class:`Battery` of a battery row's image (as the query reads it)."


async def newest_battery(db: Executor, robot_id: str) -> Battery | None:
    row = await _newest(db, keys.BATTERY, Battery, robot_id)
    return Battery(**dict(row)) if row else None


def _strategy(row: asyncpg.Record) -> Strategy:
    params = row["params"]
    return Strategy(
        code=row["code"],
        planner_scenario=row["planner_scenario"],
        controller_scenarios=tuple(row["controller_scenarios"]),
        params=dict(params) if isinstance(params, dict) else {},
    )


# params beyond migration 11's bounds (a row older than it) read as NULL, so every scenario
# takes its defaults: decoding them could fail the whole read (a parser's recursion limit)
_PARAMS = "CASE WHEN strategy_params_bounded(s.params) THEN s.params END AS params"


async def strategies(db: Executor) -> dict[str, Strategy]:
    rows = await db.fetch(
        f"SELECT code, planner_scenario, controller_scenarios, {_PARAMS} FROM strategy s"
    )
    return {r["code"]: _strategy(r) for r in rows}


async def active_strategies(db: Executor) -> dict[str, ActiveStrategy]:
    """Robot id -> the strategy it follows now (robots with no row are absent)."""
    rows = await db.fetch(
        "SELECT a.robot_id, a.resume_code, a.source, s.code, s.planner_scenario, "
        f"s.controller_scenarios, {_PARAMS} FROM active_strategy a "
        "JOIN strategy s ON s.code = a.strategy_code"
    )
    return {
        r["robot_id"]: ActiveStrategy(r["robot_id"], _strategy(r), r["resume_code"], r["source"])
        for r in rows
    }


ACTIVE_GOAL_SQL = (
    "SELECT g.id, g.robot_id, g.x, g.y, g.tolerance_m, g.yaw, g.yaw_tolerance_rad, "
    "(SELECT count(*) FROM goal_waypoint w WHERE w.goal_id = g.id) AS waypoint_count "
    "FROM goal g WHERE g.robot_id = $1 AND g.status = 'active'"
)
WAYPOINTS_SQL = (
    "SELECT seq, x, y, tolerance_m, yaw, yaw_tolerance_rad, stop, status "
    "FROM goal_waypoint WHERE goal_id = $1 ORDER BY seq"
)


async def active_goal(db: Executor, robot_id: str, known: Goal | None = None) -> Goal | None:
    """The robot's active goal with its waypoints. ``known``: the same goal as read before;
    its waypoints are kept when the goal still has as many rows (the planner's period read
    costs one indexed count, not a route of 1 000 rows)."""
    row = await db.fetchrow(ACTIVE_GOAL_SQL, robot_id)
    if row is None:
        return None
    fields = dict(row)
    count = int(fields.pop("waypoint_count"))
    goal = Goal(**fields, waypoint_count=count)
    if count == 0:
        return goal
    if known is not None and known.id == goal.id and known.waypoint_count == count:
        return replace(goal, waypoints=known.waypoints)
    rows = await db.fetch(WAYPOINTS_SQL, goal.id)
    return replace(goal, waypoints=tuple(Waypoint(**dict(r)) for r in rows))


async def charging_stations(db: Executor) -> list[ChargingStation]:
    rows = await db.fetch(
        "SELECT station_id, x, y, radius_m FROM charging_station ORDER BY station_id"
    )
    return [ChargingStation(**dict(r)) for r in rows]

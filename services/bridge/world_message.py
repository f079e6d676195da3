"""The sim's world message (``pnav/sim/world``) -> robot, map and charging_station rows.

:func:`parse_world` validates a payload into a :class:`World`; :func:`upsert_world` writes
it in one transaction, notifications after the commit: ``pnav/db/robot/{robot}`` per robot,
``pnav/db/map/_``, ``pnav/db/charging_station/_``. When to do it is
:mod:`services.bridge.world_sync`'s business.

Stations of this map that the new world no longer has are deleted, so the planner never
sends a robot to a charger that is gone. Robots are never deleted: that would cascade into
their whole history.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, cast

from common import bus
from common.contract import keys
from common.db import Database
from common.footprint import polygon_problem
from common.robotmodel import (
    DEFAULT_MODEL,
    FULL_TURN,
    MAX_ACCEL,
    MAX_BEAMS,
    MAX_NOISE_M,
    MAX_RANGE_M,
    MAX_RATE_HZ,
    load_model,
)
from services.bridge.sensor_payloads import (
    BAD_MSGPACK,
    MISSING_FIELD,
    NOT_A_MAP,
    OUT_OF_RANGE,
    WRONG_TYPE,
    MalformedMessage,
    integer,
    number,
    text,
)

MAX_CELLS = 100_000_000  # a 10 km x 10 km map at 1 m, or 1 km x 1 km at 10 cm

# A world may leave any model column out: it is then the default model's (the Burger's, as
# the robot table's defaults in schema.sql), read from models/ like any model.
_DEFAULT_ROW = load_model(DEFAULT_MODEL).robot_row()
# every number column of the robot row, with the bounds the schema's CHECKs put on it:
# (lowest, highest, lowest excluded); refused here, a bad world never reaches the table
ROBOT_NUMBERS: dict[str, tuple[float, float, bool]] = {
    "wheel_radius_m": (0.0, math.inf, True),
    "wheel_separation_m": (0.0, math.inf, True),
    "max_linear_mps": (0.0, math.inf, True),
    "max_angular_rps": (0.0, math.inf, True),
    "footprint_radius_m": (0.0, math.inf, True),
    "battery_capacity_wh": (0.0, math.inf, True),
    "max_linear_accel_mps2": (0.0, MAX_ACCEL, True),
    "max_angular_accel_rps2": (0.0, MAX_ACCEL, True),
    "lidar_angle_min_rad": (-FULL_TURN, FULL_TURN, False),
    "lidar_fov_rad": (0.0, FULL_TURN, True),
    "lidar_range_min_m": (0.0, MAX_RANGE_M, False),
    "lidar_range_max_m": (0.0, MAX_RANGE_M, True),
    "lidar_noise_m": (0.0, MAX_NOISE_M, False),
    "lidar_rate_hz": (0.0, MAX_RATE_HZ, True),
}
ROBOT_DEFAULTS: dict[str, float] = {key: cast(float, _DEFAULT_ROW[key]) for key in ROBOT_NUMBERS}
DEFAULT_BEAMS = cast(int, _DEFAULT_ROW["lidar_beams"])


@dataclass(frozen=True)
class MapInfo:
    map_id: str
    resolution: float
    origin_x: float
    origin_y: float
    origin_yaw: float
    width: int
    height: int
    grid: bytes
    source: str


@dataclass(frozen=True)
class RobotInfo:
    robot_id: str
    model: str
    wheel_radius_m: float
    wheel_separation_m: float
    max_linear_mps: float
    max_angular_rps: float
    footprint_radius_m: float
    battery_capacity_wh: float
    max_linear_accel_mps2: float
    max_angular_accel_rps2: float
    lidar_angle_min_rad: float
    lidar_fov_rad: float
    lidar_range_min_m: float
    lidar_range_max_m: float
    lidar_noise_m: float
    lidar_rate_hz: float
    lidar_beams: int
    # robot frame, counter-clockwise (common/footprint.py); None: the disc of the radius
    footprint_polygon: list[list[float]] | None = None

    def columns(self) -> dict[str, Any]:
        """The robot row's model columns (and robot_id), as CONTRACT.md names them."""
        return asdict(self)


@dataclass(frozen=True)
class StationInfo:
    station_id: str
    x: float
    y: float
    radius_m: float
    charge_power_w: float


@dataclass(frozen=True)
class World:
    name: str
    map: MapInfo
    robots: tuple[RobotInfo, ...]
    stations: tuple[StationInfo, ...]


def _mapping(value: Any, where: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise MalformedMessage(NOT_A_MAP, f"{where} must be a map")
    return value


def _array(body: dict[str, Any], key: str) -> list[Any]:
    if key not in body:
        raise MalformedMessage(MISSING_FIELD, f"'{key}' is missing")
    value = body[key]
    if not isinstance(value, list):
        raise MalformedMessage(WRONG_TYPE, f"'{key}' must be an array")
    return value


def _unique(ids: list[str], what: str) -> None:
    if len(set(ids)) != len(ids):
        raise MalformedMessage(OUT_OF_RANGE, f"duplicate {what} ids")


def _parse_map(name: str, body: dict[str, Any]) -> MapInfo:
    width = integer(body, "width", 1, MAX_CELLS)
    height = integer(body, "height", 1, MAX_CELLS)
    if width * height > MAX_CELLS:
        raise MalformedMessage(OUT_OF_RANGE, f"{width} x {height} cells is too many")
    origin = _array(body, "origin")
    if len(origin) not in (2, 3):
        raise MalformedMessage(OUT_OF_RANGE, "'origin' must be [x, y, yaw]")
    ox, oy, oyaw = (number({"origin": v}, "origin") for v in [*origin, 0.0][:3])
    grid = body.get("grid")
    if not isinstance(grid, bytes):
        raise MalformedMessage(WRONG_TYPE, "'grid' must be bytes (msgpack bin)")
    if len(grid) != width * height:
        raise MalformedMessage(OUT_OF_RANGE, f"grid has {len(grid)} bytes, not {width * height}")
    source = body.get("source", "")
    if not isinstance(source, str):
        raise MalformedMessage(WRONG_TYPE, "'source' must be a string")
    resolution = number(body, "resolution", 0.0, 1e3)
    if resolution <= 0:
        raise MalformedMessage(OUT_OF_RANGE, "'resolution' must be positive")
    return MapInfo(name, resolution, ox, oy, oyaw, width, height, grid, source)


def _parse_robot(body: dict[str, Any]) -> RobotInfo:
    robot_id = text(body, "robot_id")
    if not keys.valid_id(robot_id):
        raise MalformedMessage(OUT_OF_RANGE, f"robot id {robot_id!r} is not [A-Za-z0-9_-]+")
    for optional in ("x", "y", "yaw"):  # the start pose: checked, not stored
        if optional in body:
            number(body, optional)
    limits = {}
    for key, (lo, hi, open_lo) in ROBOT_NUMBERS.items():
        value = number(body, key, lo, hi) if key in body else ROBOT_DEFAULTS[key]
        if open_lo and value <= lo:
            raise MalformedMessage(OUT_OF_RANGE, f"'{key}' must be greater than {lo:g}")
        limits[key] = value
    if not limits["lidar_range_max_m"] > limits["lidar_range_min_m"]:
        raise MalformedMessage(OUT_OF_RANGE, "'lidar_range_max_m' must exceed lidar_range_min_m")
    beams = integer(body, "lidar_beams", 1, MAX_BEAMS) if "lidar_beams" in body else DEFAULT_BEAMS
    model = text(body, "model") if "model" in body else DEFAULT_MODEL
    polygon = body.get("footprint_polygon")
    if polygon is not None:
        problem = polygon_problem(polygon)
        if problem is not None:
            raise MalformedMessage(OUT_OF_RANGE, f"'footprint_polygon' {problem}")
        polygon = [[float(x), float(y)] for x, y in polygon]
    return RobotInfo(
        robot_id=robot_id, model=model, lidar_beams=beams, footprint_polygon=polygon, **limits
    )


def _parse_station(body: dict[str, Any]) -> StationInfo:
    radius = number(body, "radius_m", 0.0)
    power = number(body, "charge_power_w", 0.0)
    if radius <= 0 or power <= 0:
        raise MalformedMessage(OUT_OF_RANGE, "radius_m and charge_power_w must be positive")
    return StationInfo(
        text(body, "station_id"), number(body, "x"), number(body, "y"), radius, power
    )


def parse_world(payload: bytes) -> World:
    """A ``pnav/sim/world`` payload -> :class:`World`, or MalformedMessage."""
    try:
        body = bus.unpack(payload)
    except ValueError as exc:
        raise MalformedMessage(BAD_MSGPACK, str(exc)) from None
    body = _mapping(body, "the world")
    name = text(body, "name")
    world_map = _parse_map(name, _mapping(body.get("map"), "'map'"))
    robots = tuple(_parse_robot(_mapping(r, "a robot")) for r in _array(body, "robots"))
    stations = tuple(
        _parse_station(_mapping(s, "a station")) for s in _array(body, "charging_stations")
    )
    _unique([r.robot_id for r in robots], "robot")
    _unique([s.station_id for s in stations], "station")
    return World(name, world_map, robots, stations)


# every column of RobotInfo (the robot id and the model's), then the world
_ROBOT_COLUMNS = [*RobotInfo.__dataclass_fields__, "world"]
_UPSERT_ROBOT = f"""
INSERT INTO {keys.ROBOT} ({", ".join(_ROBOT_COLUMNS)}, registered_at)
VALUES ({", ".join(f"${i}" for i in range(1, len(_ROBOT_COLUMNS) + 1))}, now())
ON CONFLICT (robot_id) DO UPDATE SET
    {", ".join(f"{c} = EXCLUDED.{c}" for c in _ROBOT_COLUMNS[1:])}, registered_at = now()"""

_UPSERT_MAP = f"""
INSERT INTO {keys.MAP} (map_id, resolution_m, origin_x, origin_y, origin_yaw, width, height,
                        grid, source, loaded_at)
VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, now())
ON CONFLICT (map_id) DO UPDATE SET
    resolution_m = EXCLUDED.resolution_m, origin_x = EXCLUDED.origin_x,
    origin_y = EXCLUDED.origin_y, origin_yaw = EXCLUDED.origin_yaw, width = EXCLUDED.width,
    height = EXCLUDED.height, grid = EXCLUDED.grid, source = EXCLUDED.source,
    loaded_at = now()"""

_UPSERT_STATION = f"""
INSERT INTO {keys.CHARGING_STATION} (station_id, map_id, x, y, radius_m, charge_power_w)
VALUES ($1, $2, $3, $4, $5, $6)
ON CONFLICT (station_id) DO UPDATE SET
    map_id = EXCLUDED.map_id, x = EXCLUDED.x, y = EXCLUDED.y, radius_m = EXCLUDED.radius_m,
    charge_power_w = EXCLUDED.charge_power_w"""

_DELETE_GONE_STATIONS = f"""
DELETE FROM {keys.CHARGING_STATION} WHERE map_id = $1 AND NOT (station_id = ANY($2::text[]))"""


async def upsert_world(db: Database, world: World) -> None:
    """Write ``world``'s rows in one transaction; notifications follow the commit."""
    m = world.map
    async with db.transaction() as tx:
        await tx.conn.execute(
            _UPSERT_MAP,
            m.map_id,
            m.resolution,
            m.origin_x,
            m.origin_y,
            m.origin_yaw,
            m.width,
            m.height,
            m.grid,
            m.source,
        )
        tx.changed(keys.MAP, None)
        if world.robots:
            await tx.conn.executemany(
                _UPSERT_ROBOT,
                [(*r.columns().values(), world.name) for r in world.robots],
            )
        for r in world.robots:
            tx.changed(keys.ROBOT, r.robot_id)
        if world.stations:
            await tx.conn.executemany(
                _UPSERT_STATION,
                [
                    (s.station_id, world.name, s.x, s.y, s.radius_m, s.charge_power_w)
                    for s in world.stations
                ],
            )
        await tx.conn.execute(
            _DELETE_GONE_STATIONS, world.name, [s.station_id for s in world.stations]
        )
        tx.changed(keys.CHARGING_STATION, None)

"""The sim's world message -> robot, map and charging_station rows, once per distinct world.

The sim answers a query on ``pnav/sim/world`` and republishes the world every second or so.
:class:`WorldSync` asks once at start (and again every ``world_retry_s`` until a world is
in), listens to the republications, and upserts the rows in one transaction only when the
content differs from what it last applied: a byte-identical payload is skipped without even
decoding it, a re-encoded but equal one after decoding. Notifications go out after the
commit: ``pnav/db/robot/{robot}`` per robot, ``pnav/db/map/_``, ``pnav/db/charging_station/_``.

Stations of this map that the new world no longer has are deleted, so the planner never
sends a robot to a charger that is gone. Robots are never deleted: that would cascade into
their whole history.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import zenoh

from common import bus, log
from common.contract import keys
from common.db import Database
from services.bridge.counters import Counters, RateLimitedLog
from services.bridge.messages import (
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

logger = logging.getLogger("pnav.bridge.world")

MAX_CELLS = 100_000_000  # a 10 km x 10 km map at 1 m, or 1 km x 1 km at 10 cm

# The robot table's defaults (schema.sql): a world may leave any limit out.
ROBOT_DEFAULTS: dict[str, float] = {
    "wheel_radius_m": 0.033,
    "wheel_separation_m": 0.160,
    "max_linear_mps": 0.22,
    "max_angular_rps": 2.84,
    "footprint_radius_m": 0.105,
    "battery_capacity_wh": 19.98,
}
DEFAULT_MODEL = "turtlebot3_burger"


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
    for key, default in ROBOT_DEFAULTS.items():
        value = number(body, key, 0.0) if key in body else default
        if value <= 0:
            raise MalformedMessage(OUT_OF_RANGE, f"'{key}' must be positive")
        limits[key] = value
    model = text(body, "model") if "model" in body else DEFAULT_MODEL
    return RobotInfo(robot_id=robot_id, model=model, **limits)


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


_UPSERT_ROBOT = f"""
INSERT INTO {keys.ROBOT} (robot_id, model, wheel_radius_m, wheel_separation_m, max_linear_mps,
                          max_angular_rps, footprint_radius_m, battery_capacity_wh, world,
                          registered_at)
VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, now())
ON CONFLICT (robot_id) DO UPDATE SET
    model = EXCLUDED.model, wheel_radius_m = EXCLUDED.wheel_radius_m,
    wheel_separation_m = EXCLUDED.wheel_separation_m,
    max_linear_mps = EXCLUDED.max_linear_mps, max_angular_rps = EXCLUDED.max_angular_rps,
    footprint_radius_m = EXCLUDED.footprint_radius_m,
    battery_capacity_wh = EXCLUDED.battery_capacity_wh, world = EXCLUDED.world,
    registered_at = now()"""

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
                [
                    (
                        r.robot_id,
                        r.model,
                        r.wheel_radius_m,
                        r.wheel_separation_m,
                        r.max_linear_mps,
                        r.max_angular_rps,
                        r.footprint_radius_m,
                        r.battery_capacity_wh,
                        world.name,
                    )
                    for r in world.robots
                ],
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


class WorldSync:
    """Keeps the world's rows in step with the sim (see the module docstring)."""

    def __init__(
        self,
        session: zenoh.Session,
        db: Database,
        counters: Counters,
        *,
        retry_s: float,
        on_applied: Callable[[World], None],
    ) -> None:
        self.session = session
        self.db = db
        self.counters = counters
        self.retry_s = retry_s
        self.on_applied = on_applied
        self.world: World | None = None
        self._applied_payload: bytes | None = None
        self._refused_payload: bytes | None = None
        self._latest: bytes | None = None
        self._wake = asyncio.Event()
        self._alerts = RateLimitedLog(logger, period_s=30.0)
        self._subscriber: zenoh.Subscriber[None] | None = None
        self._tasks: list[asyncio.Task[None]] = []

    def start(self) -> None:
        self._subscriber = bus.subscribe(self.session, keys.SIM_WORLD, self.offer)
        self._tasks = [
            asyncio.create_task(self._apply_loop(), name="world-apply"),
            asyncio.create_task(self._query_loop(), name="world-query"),
        ]

    async def close(self) -> None:
        if self._subscriber is not None:
            self._subscriber.undeclare()
            self._subscriber = None
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        self._tasks = []

    def offer(self, key: str, payload: bytes) -> None:
        """A world payload arrived (publication or query reply); runs on the loop."""
        if payload == self._applied_payload:
            self.counters.worlds_unchanged += 1
            return
        if payload == self._refused_payload:
            self.counters.worlds_malformed += 1
            return
        self._latest = payload  # only the newest matters if several queue up
        self._wake.set()

    def query(self) -> None:
        """Ask the sim's queryable for its world; replies arrive through :meth:`offer`."""
        loop = asyncio.get_running_loop()

        def on_reply(reply: zenoh.Reply) -> None:  # on a Zenoh thread
            sample = reply.ok
            if sample is None:
                return
            with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
                loop.call_soon_threadsafe(
                    self.offer, str(sample.key_expr), sample.payload.to_bytes()
                )

        self.session.get(keys.SIM_WORLD, on_reply, timeout=max(self.retry_s, 1.0))

    async def _query_loop(self) -> None:
        while self.world is None:
            try:
                self.query()
            except Exception as exc:
                self._alerts.warning("query", "world query failed", error=repr(exc))
            await asyncio.sleep(self.retry_s)

    async def _apply_loop(self) -> None:
        while True:
            await self._wake.wait()
            self._wake.clear()
            payload, self._latest = self._latest, None
            if payload is None or payload == self._applied_payload:
                continue
            try:
                world = parse_world(payload)
            except MalformedMessage as exc:
                self._refused_payload = payload
                self.counters.worlds_malformed += 1
                self._alerts.warning(exc.reason, "malformed world ignored", reason=exc.reason)
                continue
            if world == self.world:
                self._applied_payload = payload
                self.counters.worlds_unchanged += 1
                continue
            try:
                await upsert_world(self.db, world)
            except Exception as exc:
                # Postgres away or refusing: try again with the next republication
                self._alerts.warning("upsert", "world not written", error=repr(exc))
                await asyncio.sleep(1.0)
                continue
            self.world = world
            self._applied_payload = payload
            self.counters.worlds_applied += 1
            log.event(
                logger,
                logging.INFO,
                "world applied",
                world=world.name,
                robots=",".join(r.robot_id for r in world.robots),
                stations=len(world.stations),
                map=f"{world.map.width}x{world.map.height}@{world.map.resolution}",
            )
            self.on_applied(world)

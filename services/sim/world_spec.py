"""World files: a map_server map plus the robots, charging stations and extra obstacles.

A world file is YAML (format in docs/SIM.md)::

    name: warehouse                  # optional, defaults to the file name
    map: maps/warehouse.yaml         # a map_server YAML, relative to this file
    robots:
      - {id: r1, x: 1.0, y: 1.0, yaw: 0.0, battery: 80}   # battery: start percent, optional
      - {id: r2, x: 2.0, y: 1.0, model: jackal}          # a robot model (models/), optional
      - {id: r3, x: 3.0, y: 1.0, model: {name: jackal, max_linear_mps: 1.5}}  # overridden
    charging_stations:
      - {id: dock1, x: 0.6, y: 0.6, radius: 0.3, power: 20.0}
    obstacles:                       # not drawn in the map: the robot meets them unannounced
      - {type: box, x: 3.0, y: 2.0, yaw: 0.3, size: [0.4, 0.4, 0.4]}
      - {type: cylinder, x: 4.0, y: 2.5, radius: 0.15, height: 0.5}
    movers:                          # moving obstacles (services/sim/mover.py), not in the map
      - {name: walker, radius: 0.25, path: [[1, 2], [6, 2]], speed: 0.8, mode: back_and_forth}

A robot that names no model is the default one (``pnav up --model``, else the Burger). A bare
map_server YAML is accepted too: the world is then the map with one robot of the default
model placed on the first free spot. Every problem raises WorldError naming the file and the
problem (a bad model: the world file, the robot and the model file's field).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import yaml

from common import yamldoc
from common.contract import keys
from common.errors import ModelError, WorldError
from common.robotmodel import DEFAULT_MODEL, ROBOT_FIELDS, RobotModel, load_model
from services.sim.entry import EntryReader
from services.sim.mapserver import FREE, OccupancyGrid, load_map
from services.sim.mapserver import REQUIRED_KEYS as MAP_KEYS
from services.sim.mover import MoverSpec, parse_movers
from services.sim.robot import BURGER

DEFAULT_STATION_RADIUS_M = 0.3
DEFAULT_CHARGE_POWER_W = 20.0
DEFAULT_WALL_HEIGHT_M = 0.3

# The keys of each mapping of a world file: any other is refused, naming the closest one.
# ``benchmark`` is the navigation benchmark's block (docs/NAVBENCH.md), read by pnav.bench.nav.
WORLD_KEYS = (
    "name",
    "map",
    "robots",
    "charging_stations",
    "obstacles",
    "movers",
    "wall_height",
    "benchmark",
)
ROBOT_KEYS = ("id", "x", "y", "yaw", "battery", "model")
STATION_KEYS = ("id", "x", "y", "radius", "power")
_OBSTACLE = ("name", "type", "x", "y", "yaw")
OBSTACLE_KEYS = {"box": (*_OBSTACLE, "size"), "cylinder": (*_OBSTACLE, "radius", "height")}
# a robot model's fields, written on a robot entry instead of in its ``model``
MODEL_KEYS = frozenset((*ROBOT_FIELDS, "lidar"))


@dataclass(frozen=True)
class RobotSpec:
    robot_id: str
    x: float
    y: float
    yaw: float = 0.0
    battery_percent: float | None = None  # None: full
    model: RobotModel = BURGER


@dataclass(frozen=True)
class StationSpec:
    station_id: str
    x: float
    y: float
    radius_m: float = DEFAULT_STATION_RADIUS_M
    charge_power_w: float = DEFAULT_CHARGE_POWER_W


@dataclass(frozen=True)
class ObstacleSpec:
    name: str
    shape: str  # "box" or "cylinder"
    x: float
    y: float
    yaw: float = 0.0
    size: tuple[float, float, float] = (0.0, 0.0, 0.0)  # box: full extents; cylinder: 2r, 2r, h

    def overlaps_disc(self, x: float, y: float, radius: float) -> bool:
        dx, dy = x - self.x, y - self.y
        if self.shape == "cylinder":
            return math.hypot(dx, dy) < radius + self.size[0] / 2.0
        c, s = math.cos(-self.yaw), math.sin(-self.yaw)
        lx, ly = c * dx - s * dy, s * dx + c * dy
        hx, hy = self.size[0] / 2.0, self.size[1] / 2.0
        qx, qy = max(abs(lx) - hx, 0.0), max(abs(ly) - hy, 0.0)
        return math.hypot(qx, qy) < radius


@dataclass(frozen=True)
class World:
    name: str
    source: str
    grid: OccupancyGrid
    robots: tuple[RobotSpec, ...]
    stations: tuple[StationSpec, ...] = ()
    obstacles: tuple[ObstacleSpec, ...] = ()
    movers: tuple[MoverSpec, ...] = ()  # where each is at sim time 0 counts for the starts
    wall_height_m: float = DEFAULT_WALL_HEIGHT_M
    # the model of robots that name none: extra robots (with_robot_count) are of this one
    default_model: RobotModel = BURGER

    @property
    def models(self) -> tuple[RobotModel, ...]:
        """The robots' models, in robot order."""
        return tuple(r.model for r in self.robots)

    def blocked(self, x: float, y: float, radius: float) -> str | None:
        """What a disc at (x, y) would overlap, or None: 'outside the map', 'a wall', an
        obstacle's name."""
        if not self.grid.contains(x, y):
            return "outside the map"
        if self.grid.occupied_near(x, y, radius):
            return "an occupied map cell"
        for obstacle in self.obstacles:
            if obstacle.overlaps_disc(x, y, radius):
                return f"obstacle {obstacle.name}"
        for mover in self.movers:
            if mover.overlaps_disc(0.0, x, y, radius):
                return f"mover {mover.name} (where it is at sim time 0)"
        return None

    def with_robot_count(self, count: int, *, spacing_m: float = 0.6) -> World:
        """This world with exactly ``count`` robots: the first ones of the file, then extra
        robots on free spots (deterministic, scanning the map from its lower-left corner)."""
        if count < 1:
            raise WorldError(f"{self.source}: the number of robots must be at least 1")
        robots = list(self.robots[:count])
        used = {r.robot_id for r in robots}
        clearance = self.default_model.footprint_radius_m + 0.15
        step = max(spacing_m / 2.0, self.grid.resolution)
        ox, oy = self.grid.cell_to_world(0, 0)
        width_m = self.grid.width * self.grid.resolution
        height_m = self.grid.height * self.grid.resolution
        n = 1
        y = oy + clearance
        while len(robots) < count and y < oy + height_m:
            x = ox + clearance
            while len(robots) < count and x < ox + width_m:
                if self._spawnable(x, y, clearance, robots, spacing_m):
                    while f"r{n}" in used:
                        n += 1
                    spec = RobotSpec(f"r{n}", round(x, 3), round(y, 3), model=self.default_model)
                    robots.append(spec)
                    used.add(f"r{n}")
                x += step
            y += step
        if len(robots) < count:
            raise WorldError(f"{self.source}: no free room for {count} robots")
        return replace(self, robots=tuple(robots))

    def _spawnable(
        self, x: float, y: float, clearance: float, robots: list[RobotSpec], spacing: float
    ) -> bool:
        if self.blocked(x, y, clearance) is not None or self.grid.value_at(x, y) != FREE:
            return False
        if any(math.hypot(x - s.x, y - s.y) < s.radius_m + clearance for s in self.stations):
            return False  # keep chargers clear for the robots that need them
        return all(
            math.hypot(x - r.x, y - r.y) >= max(spacing, clearance + r.model.footprint_radius_m)
            for r in robots
        )

    def message(self) -> dict[str, Any]:
        """The ``pnav/sim/world`` payload (CONTRACT.md); robots at their start poses."""
        g = self.grid
        return {
            "name": self.name,
            "map": {
                "resolution": g.resolution,
                "origin": [g.origin[0], g.origin[1], g.origin[2]],
                "width": g.width,
                "height": g.height,
                "grid": g.to_bytes(),
                "source": g.source,
            },
            "robots": [
                {"robot_id": r.robot_id, "x": r.x, "y": r.y, "yaw": r.yaw, **r.model.robot_row()}
                for r in self.robots
            ],
            "charging_stations": [
                {
                    "station_id": s.station_id,
                    "x": s.x,
                    "y": s.y,
                    "radius_m": s.radius_m,
                    "charge_power_w": s.charge_power_w,
                }
                for s in self.stations
            ],
            # only in a world with movers: a static world's message is as it always was
            **({"movers": [m.message() for m in self.movers]} if self.movers else {}),
        }


# -- loading ---------------------------------------------------------------------------------
def _list(path: Path, doc: dict[str, Any], key: str) -> list[Any]:
    value = doc.get(key) or []
    if not isinstance(value, list):
        raise WorldError(f"{path}: '{key}' must be a list, got {value!r}")
    return value


def _robot(path: Path, i: int, doc: Any, default: RobotModel) -> RobotSpec:
    r = EntryReader(path, doc, f"robots[{i}]")
    key = yamldoc.unknown_key(r.doc, ROBOT_KEYS)
    if key in MODEL_KEYS:
        raise r.error(
            f"{key!r} is a field of the robot model, not of the robot entry: write it in "
            f"'model' (model: {{name: {DEFAULT_MODEL}, {key}: ...}}; docs/SIM.md)"
        )
    r.only(ROBOT_KEYS)
    battery = r.doc.get("battery")
    if battery is not None:
        battery = r.number("battery")
        if not 0.0 <= battery <= 100.0:
            raise r.error(f"'battery' is a percentage within [0, 100], got {battery}")
    model = _model(r, default)
    x, y, yaw = r.number("x"), r.number("y"), r.number("yaw", 0.0)
    return RobotSpec(r.ident("id"), x, y, yaw, battery, model)


def _model(r: EntryReader, default: RobotModel) -> RobotModel:
    """A robot entry's ``model``: a name (``jackal``), or a mapping of a ``name`` and the
    fields it overrides (``{name: jackal, max_linear_mps: 1.5, lidar: {rate_hz: 10}}``)."""
    spec = r.doc.get("model")
    if spec is None:
        return default
    overrides: dict[str, Any] = {}
    if isinstance(spec, dict):
        overrides = dict(spec)
        spec = overrides.pop("name", None)
        if spec is None:
            raise r.error("model: a mapping needs 'name' (the model its fields override)")
    if not isinstance(spec, str) or not spec:
        raise r.error(f"model: must be a model name or a mapping with 'name', got {spec!r}")
    try:
        return load_model(spec, overrides or None)
    except ModelError as exc:
        raise r.error(f"model: {exc}") from None


def resolve_default_model(name: str | None) -> RobotModel:
    """The model of robots that name none: ``name`` (``--model``), else the Burger."""
    return BURGER if name is None or name == DEFAULT_MODEL else load_model(name)


def _station(path: Path, i: int, doc: Any) -> StationSpec:
    r = EntryReader(path, doc, f"charging_stations[{i}]")
    r.only(STATION_KEYS)
    return StationSpec(
        r.ident("id"),
        r.number("x"),
        r.number("y"),
        r.positive("radius", DEFAULT_STATION_RADIUS_M),
        r.positive("power", DEFAULT_CHARGE_POWER_W),
    )


def _obstacle(path: Path, i: int, doc: Any) -> ObstacleSpec:
    r = EntryReader(path, doc, f"obstacles[{i}]")
    shape = r.doc.get("type", "box")
    if shape in OBSTACLE_KEYS:
        r.only(OBSTACLE_KEYS[shape], f": a {shape} has no such key")
    name = r.ident("name", f"{shape}_{i}")
    x, y, yaw = r.number("x"), r.number("y"), r.number("yaw", 0.0)
    if shape == "box":
        size = r.doc.get("size")
        if (
            not isinstance(size, list)
            or len(size) != 3
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in size)
            or not all(math.isfinite(v) and v > 0 for v in size)
        ):
            raise r.error(f"a box needs 'size' [sx, sy, sz] of positive numbers, got {size!r}")
        return ObstacleSpec(name, "box", x, y, yaw, (size[0], size[1], size[2]))
    if shape == "cylinder":
        radius, height = r.positive("radius"), r.positive("height", 0.5)
        return ObstacleSpec(name, "cylinder", x, y, yaw, (2 * radius, 2 * radius, height))
    raise r.error(f"'type' must be box or cylinder, got {shape!r}")


def _check_start(world: World, path: Path, spec: RobotSpec, placed: list[RobotSpec]) -> None:
    radius = spec.model.footprint_radius_m
    what = world.blocked(spec.x, spec.y, radius)
    if what == "outside the map":
        raise WorldError(
            f"{path}: robot {spec.robot_id} start pose ({spec.x}, {spec.y}) is outside the map"
        )
    if what is not None:
        raise WorldError(
            f"{path}: robot {spec.robot_id} start pose ({spec.x}, {spec.y}) is inside an "
            f"obstacle ({what})"
        )
    for other in placed:
        if math.hypot(spec.x - other.x, spec.y - other.y) < radius + other.model.footprint_radius_m:
            raise WorldError(
                f"{path}: robot {spec.robot_id} start pose overlaps robot {other.robot_id}"
            )


def read_world_yaml(path: Path) -> Any:
    """A world file's YAML document; WorldError naming the file if it cannot be read."""
    try:
        return yamldoc.load(path.read_text())
    except FileNotFoundError:
        raise WorldError(f"{path}: world file not found") from None
    except (OSError, yaml.YAMLError) as exc:
        raise WorldError(f"{path}: cannot read world YAML: {exc}") from None


def load_world(path: str | Path, model: str | None = None) -> World:
    """Load and check a world file (or a bare map_server YAML); ``model`` names the model of
    every robot that names none (default: the Burger)."""
    path = Path(path)
    default = resolve_default_model(model)
    doc = read_world_yaml(path)
    if not isinstance(doc, dict):
        raise WorldError(f"{path}: a world file must be a YAML mapping")

    if "map" not in doc and "robots" not in doc and any(k in doc for k in MAP_KEYS):
        # a bare map_server map: one robot on the first free spot
        grid = load_map(path)
        bare = World(name=path.stem, source=str(path), grid=grid, robots=(), default_model=default)
        return bare.with_robot_count(1)

    key = yamldoc.unknown_key(doc, WORLD_KEYS)
    if key is not None:
        raise WorldError(f"{path}: {yamldoc.unknown_key_problem(key, WORLD_KEYS)}")
    if "map" not in doc:
        raise WorldError(f"{path}: missing required key 'map' (a map_server YAML file)")
    if not isinstance(doc["map"], str):
        raise WorldError(f"{path}: 'map' must be a file name, got {doc['map']!r}")
    try:
        grid = load_map(path.parent / doc["map"])
    except WorldError as exc:  # name the world file too: that is what the user passed
        raise WorldError(f"{path}: {exc}") from None
    name = str(doc.get("name") or path.stem)
    if not keys.valid_id(name):
        raise WorldError(f"{path}: name {name!r} must match [A-Za-z0-9_-]+")
    wall_height = EntryReader(path, doc, "world").positive("wall_height", DEFAULT_WALL_HEIGHT_M)

    robot_docs = _list(path, doc, "robots")
    if not robot_docs:
        raise WorldError(f"{path}: missing required key 'robots' (at least one robot)")
    robots = [_robot(path, i, d, default) for i, d in enumerate(robot_docs)]
    stations = [_station(path, i, d) for i, d in enumerate(_list(path, doc, "charging_stations"))]
    obstacles = [_obstacle(path, i, d) for i, d in enumerate(_list(path, doc, "obstacles"))]
    movers = parse_movers(path, _list(path, doc, "movers"))
    for label, ids in (
        ("robot", [r.robot_id for r in robots]),
        ("charging station", [s.station_id for s in stations]),
        # a collision names what the robot touched: an obstacle and a mover share the names
        ("obstacle or mover", [o.name for o in obstacles] + [m.name for m in movers]),
    ):
        dupes = sorted({i for i in ids if ids.count(i) > 1})
        if dupes:
            raise WorldError(f"{path}: duplicate {label} id(s) {', '.join(dupes)}")

    world = World(
        name=name,
        source=str(path),
        grid=grid,
        robots=tuple(robots),
        stations=tuple(stations),
        obstacles=tuple(obstacles),
        movers=movers,
        wall_height_m=wall_height,
        default_model=default,
    )
    placed: list[RobotSpec] = []
    for spec in robots:
        _check_start(world, path, spec, placed)
        placed.append(spec)
    return world

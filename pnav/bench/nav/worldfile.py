"""Benchmark worlds on disk: a map_server map, a world file the sim loads, and its
``benchmark:`` section (fields in docs/NAVBENCH.md).

For a world named N in folder D::

    D/N.yaml          the world file: name, map, one robot r1 at the start, benchmark
    D/maps/N.yaml     the map_server YAML (0.05 m pixels, origin at (0, 0))
    D/maps/N.pgm      the image: 0 occupied, 254 free, row 0 on top

The sim's world loader reads ``name``, ``map`` and ``robots`` and ignores ``benchmark``;
``read_benchmark`` and ``load_suite`` read it back for a benchmark runner.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import yaml

from common import yamldoc
from common.errors import WorldError
from pnav.bench.nav import suitefile
from pnav.bench.nav.difficulty import Difficulty
from pnav.bench.nav.generator import LEVELS, GeneratedWorld
from pnav.bench.nav.robots import RobotFit
from pnav.bench.nav.scores import GOAL_TOLERANCE_M, TOP_SPEED_MPS, default_time_limit, optimal_time
from pnav.bench.nav.search import BoolGrid, Point
from pnav.bench.nav.suitefile import FORMAT
from services.sim.mapserver import OCCUPIED, OccupancyGrid, load_map
from services.sim.mover import MoverSpec
from services.sim.world_spec import ObstacleSpec, load_world, read_world_yaml


def world_document(world: GeneratedWorld) -> dict[str, Any]:
    """The world file's content (plain YAML types, rounded for a stable text)."""
    length = world.reference.length_m
    rule, layout = world.rule, world.layout
    return {
        "name": world.name,
        "map": f"maps/{world.name}.yaml",
        "robots": [suitefile.robot_entry(world)],
        "benchmark": {
            "format": FORMAT,
            **suitefile.route_fields(world, GOAL_TOLERANCE_M),
            "optimal_time_s": suitefile.rounded(optimal_time(length)),
            "time_limit_s": default_time_limit(length),
            "top_speed_mps": TOP_SPEED_MPS,
            "footprint_radius_m": layout.footprint_radius_m,
            "fill_ratio": suitefile.rounded(world.fill_ratio),
            "attempts": world.attempts,
            "generator": {
                **suitefile.automaton_fields(rule),
                **suitefile.field_fields(layout),
                "zone_rows": layout.zone_rows,
                "margin_m": layout.margin_m,
            },
            **suitefile.reference_fields(world),
        },
    }


def write_world(world: GeneratedWorld, folder: Path, *, header: str = "") -> Path:
    """Write the world file, its map YAML and its PGM under ``folder``; the world file's path.
    ``header`` becomes comment lines on top of the world file."""
    return suitefile.write_world_files(world, folder, world.occupied, world_document(world), header)


@dataclass(frozen=True)
class BenchmarkWorld:
    """What a benchmark runner needs of one world file."""

    name: str
    world_file: Path
    map_file: Path
    level: str
    seed: int
    start: tuple[float, float, float]  # x, y, yaw
    goal: Point
    goal_tolerance_m: float
    reference_length_m: float
    reference_path: tuple[Point, ...]
    optimal_time_s: float
    time_limit_s: float
    top_speed_mps: float
    footprint_radius_m: float
    fill_ratio: float
    difficulty: Difficulty
    generator: dict[str, Any]
    # in the world file but not on the map: only the lidar sees them (the sim's `obstacles`)
    obstacles: tuple[ObstacleSpec, ...] = ()
    # moving obstacles (the sim's `movers`): only the lidar sees them either
    movers: tuple[MoverSpec, ...] = ()
    # "barn": obstacles only in the sim world (barnfile.py); "dynabarn": movers (dynabarn.py)
    protocol: str = "default"
    model: str = ""  # the robot model the world was made for ("": the Burger, before models)

    @property
    def inflation_m(self) -> float:
        """The footprint radius plus the generator's margin: what the path was checked for."""
        return self.footprint_radius_m + float(self.generator.get("margin_m", 0.05))

    def grid(self) -> OccupancyGrid:
        """The world's map (loads the PGM; WorldError if it cannot)."""
        return load_map(self.map_file)


def occupied_cells(grid: OccupancyGrid) -> BoolGrid:
    """A map's occupied cells, bool [row, col], row 0 at the bottom."""
    occupied: BoolGrid = grid.cells == OCCUPIED
    return occupied


def _numbers(path: Path, doc: dict[str, Any], key: str, count: int) -> list[float]:
    value = doc.get(key)
    if (
        not isinstance(value, list)
        or len(value) != count
        or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
        or not all(math.isfinite(v) for v in value)
    ):
        raise WorldError(f"{path}: benchmark.{key} must be {count} numbers, got {value!r}")
    return [float(v) for v in value]


def _number(path: Path, doc: dict[str, Any], key: str) -> float:
    return _numbers(path, {key: [doc.get(key)]}, key, 1)[0]


def read_benchmark(path: str | Path) -> BenchmarkWorld:
    """The benchmark fields of a world file; WorldError (naming the file) when it has no
    ``benchmark`` section or a field is missing or malformed."""
    path = Path(path)
    doc = read_world_yaml(path)
    if not isinstance(doc, dict) or not isinstance(doc.get("benchmark"), dict):
        raise WorldError(f"{path}: not a benchmark world (no 'benchmark' mapping)")
    if not isinstance(doc.get("map"), str):
        raise WorldError(f"{path}: 'map' must be a file name")
    bench = doc["benchmark"]
    if bench.get("format") != FORMAT:
        raise WorldError(f"{path}: benchmark.format {bench.get('format')!r} is not {FORMAT}")
    points = bench.get("reference_path")
    if not isinstance(points, list) or len(points) < 2:
        raise WorldError(f"{path}: benchmark.reference_path must list at least 2 points")
    path_points = tuple(
        (p[0], p[1]) for p in (_numbers(path, {"point": q}, "point", 2) for q in points)
    )
    difficulty = bench.get("difficulty")
    try:
        parsed = Difficulty.from_json(difficulty if isinstance(difficulty, dict) else {})
    except (KeyError, TypeError, ValueError):
        raise WorldError(f"{path}: benchmark.difficulty is incomplete: {difficulty!r}") from None
    sx, sy, syaw = _numbers(path, bench, "start", 3)
    gx, gy = _numbers(path, bench, "goal", 2)
    generator = bench.get("generator")
    sim_world = load_world(path) if doc.get("obstacles") or doc.get("movers") else None
    return BenchmarkWorld(
        name=str(doc.get("name") or path.stem),
        world_file=path,
        map_file=path.parent / doc["map"],
        level=str(bench.get("level", "")),
        seed=int(_number(path, bench, "seed")),
        start=(sx, sy, syaw),
        goal=(gx, gy),
        goal_tolerance_m=_number(path, bench, "goal_tolerance_m"),
        reference_length_m=_number(path, bench, "reference_path_length_m"),
        reference_path=path_points,
        optimal_time_s=_number(path, bench, "optimal_time_s"),
        time_limit_s=_number(path, bench, "time_limit_s"),
        top_speed_mps=_number(path, bench, "top_speed_mps"),
        footprint_radius_m=_number(path, bench, "footprint_radius_m"),
        fill_ratio=_number(path, bench, "fill_ratio"),
        difficulty=parsed,
        generator=generator if isinstance(generator, dict) else {},
        # parsed (and checked) as the sim parses them; only then is the map loaded twice
        obstacles=sim_world.obstacles if sim_world else (),
        movers=sim_world.movers if sim_world else (),
        protocol=str(bench.get("protocol", "default")),
        model=str(bench.get("model", "")),
    )


def is_benchmark_world(path: Path) -> bool:
    try:
        doc = yamldoc.load(path.read_text())
    except (OSError, yaml.YAMLError):
        return False
    return isinstance(doc, dict) and isinstance(doc.get("benchmark"), dict)


def load_suite(folder: str | Path) -> list[BenchmarkWorld]:
    """Every benchmark world file directly in ``folder``, easy to hard, then by name."""
    folder = Path(folder)
    if not folder.is_dir():
        raise WorldError(f"{folder}: no such suite folder")
    worlds = [read_benchmark(p) for p in sorted(folder.glob("*.yaml")) if is_benchmark_world(p)]
    if not worlds:
        raise WorldError(f"{folder}: no benchmark world files (*.yaml with 'benchmark:')")
    order = {level: i for i, level in enumerate(LEVELS)}
    return sorted(worlds, key=lambda w: (order.get(w.level, len(order)), w.name))


def for_model(world: BenchmarkWorld, robot: RobotFit, folder: Path) -> BenchmarkWorld:
    """``world`` run and scored with ``robot``: OT at its top speed, the BARN protocol's time
    limit for that speed (the default protocol keeps the world's), and, when the world was
    made for another model (or names none), a copy of its world file under ``folder`` whose
    robot is this model (the map and the obstacles unchanged)."""
    from pnav.bench.nav import barn, dynabarn
    from pnav.bench.nav.scores import optimal_time

    limit = world.time_limit_s
    if world.protocol in (barn.PROTOCOL, dynabarn.PROTOCOL):
        limit = barn.time_limit(robot.max_linear_mps)
    world_file = world.world_file
    if robot.name != world.model:
        doc = yamldoc.load(world.world_file.read_text())
        doc["map"] = str(world.map_file.resolve())  # the copy lives elsewhere
        for entry in doc["robots"]:
            entry["model"] = robot.world_ref
        folder.mkdir(parents=True, exist_ok=True)
        world_file = folder / f"{world.name}__{robot.name}.yaml"
        world_file.write_text(yaml.safe_dump(doc, sort_keys=False, default_flow_style=None))
    return replace(
        world,
        world_file=world_file,
        top_speed_mps=robot.max_linear_mps,
        optimal_time_s=optimal_time(world.reference_length_m, robot.max_linear_mps),
        time_limit_s=limit,
        model=robot.name,
    )


def too_big(worlds: Sequence[BenchmarkWorld], robot: RobotFit) -> list[str]:
    """The worlds whose path was checked for a smaller robot than ``robot``: it may not fit
    through them."""
    return [w.name for w in worlds if robot.footprint_radius_m > w.footprint_radius_m + 1e-9]

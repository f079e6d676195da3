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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from common import yamldoc
from common.errors import WorldError
from pnav.navbench.difficulty import Difficulty
from pnav.navbench.generator import LEVELS, ORIGIN, GeneratedWorld
from pnav.navbench.metrics import GOAL_TOLERANCE_M, TOP_SPEED_MPS, default_time_limit, optimal_time
from pnav.navbench.search import BoolGrid, Point
from services.sim.mapserver import OCCUPIED, OccupancyGrid, encode_pgm, load_map, map_yaml
from services.sim.mover import MoverSpec
from services.sim.world import ObstacleSpec, load_world, read_world_yaml

FORMAT = 1
FREE_PX, OCCUPIED_PX = 254, 0  # as map_saver writes them


def _r(value: float, digits: int = 4) -> float:
    return round(float(value), digits)


def world_document(world: GeneratedWorld) -> dict[str, Any]:
    """The world file's content (plain YAML types, rounded for a stable text)."""
    x, y, yaw = world.start
    length = world.reference.length_m
    rule, layout = world.rule, world.layout
    return {
        "name": world.name,
        "map": f"maps/{world.name}.yaml",
        "robots": [{"id": "r1", "x": _r(x), "y": _r(y), "yaw": _r(yaw, 6)}],
        "benchmark": {
            "format": FORMAT,
            "level": world.level,
            "seed": world.seed,
            "start": [_r(x), _r(y), _r(yaw, 6)],
            "goal": [_r(world.goal[0]), _r(world.goal[1])],
            "goal_tolerance_m": GOAL_TOLERANCE_M,
            "reference_path_length_m": _r(length),
            "optimal_time_s": _r(optimal_time(length)),
            "time_limit_s": default_time_limit(length),
            "top_speed_mps": TOP_SPEED_MPS,
            "footprint_radius_m": layout.footprint_radius_m,
            "fill_ratio": _r(world.fill_ratio),
            "attempts": world.attempts,
            "generator": {
                "method": "cellular_automaton",
                "fill_probability": rule.fill_probability,
                "smoothing_iterations": rule.smoothing_iterations,
                "fill_threshold": rule.fill_threshold,
                "clear_threshold": rule.clear_threshold,
                "cell_m": layout.cell_m,
                "field_cells": [layout.field_cols, layout.field_rows],
                "zone_rows": layout.zone_rows,
                "margin_m": layout.margin_m,
            },
            "difficulty": world.difficulty.to_json(),
            "reference_path": [[_r(px), _r(py)] for px, py in world.reference.points],
        },
    }


def write_world(world: GeneratedWorld, folder: Path, *, header: str = "") -> Path:
    """Write the world file, its map YAML and its PGM under ``folder``; the world file's path.
    ``header`` becomes comment lines on top of the world file."""
    maps = folder / "maps"
    maps.mkdir(parents=True, exist_ok=True)
    pixels = np.where(world.occupied, OCCUPIED_PX, FREE_PX).astype(np.uint8)
    (maps / f"{world.name}.pgm").write_bytes(encode_pgm(np.flipud(pixels)))
    (maps / f"{world.name}.yaml").write_text(
        map_yaml(f"{world.name}.pgm", world.layout.resolution_m, ORIGIN[0], ORIGIN[1])
    )
    comment = "".join(f"# {line}\n".replace("# \n", "#\n") for line in header.splitlines())
    body = yaml.safe_dump(world_document(world), sort_keys=False, default_flow_style=None)
    path = folder / f"{world.name}.yaml"
    path.write_text(comment + body)
    return path


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

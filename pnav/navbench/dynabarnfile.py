"""Dynamic BARN-protocol worlds on disk (``pnav.navbench.dynabarn``), and their SUITE.md.

The files are the BARN protocol's (``pnav.navbench.barnfile``): ``D/N.yaml``,
``D/maps/N.{yaml,pgm}`` (the walls only), the robot naming its ``model``. The world file's
``movers`` are the sim's moving obstacles (docs/SIM.md); it has no ``obstacles``. The
``benchmark`` section says ``protocol: dynabarn``, with BARN's goal tolerance and time limit
and the generator's level (how many movers, how fast).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from pnav.navbench.barn import GOAL_TOLERANCE_M, WALL_HEIGHT_M, time_limit
from pnav.navbench.dynabarn import (
    LEVELS,
    MIN_SPEED_MPS,
    MOVER_HEIGHT_M,
    PROTOCOL,
    DynaBarnWorld,
)
from pnav.navbench.generator import ORIGIN
from pnav.navbench.metrics import optimal_time
from pnav.navbench.worldfile import FORMAT, FREE_PX, OCCUPIED_PX
from services.sim.mapserver import encode_pgm, map_yaml
from services.sim.mover import MoverSpec


def _r(value: float, digits: int = 4) -> float:
    return round(float(value), digits)


class _Inline(dict[str, Any]):
    """A mapping written on one line: a mover per line keeps the file readable."""


class _Dumper(yaml.SafeDumper):
    pass


_Dumper.add_representer(
    _Inline, lambda dumper, data: dumper.represent_mapping("tag:yaml.org,2002:map", data, True)
)


def mover_entries(world: DynaBarnWorld) -> list[dict[str, Any]]:
    return [
        _Inline(
            {
                "name": c.name,
                "type": "cylinder",
                "radius": c.radius_m,
                "height": MOVER_HEIGHT_M,
                "path": [list(c.a), list(c.b)],
                "speed": c.speed_mps,
                "mode": "back_and_forth",
                "offset": c.offset_m,
            }
        )
        for c in world.crossings
    ]


def mover_specs(world: DynaBarnWorld) -> list[MoverSpec]:
    """The movers as the sim reads them (for the preview)."""
    return [
        MoverSpec(
            c.name,
            "cylinder",
            (2 * c.radius_m, 2 * c.radius_m, MOVER_HEIGHT_M),
            (c.a, c.b),
            c.speed_mps,
            "back_and_forth",
            c.offset_m,
        )
        for c in world.crossings
    ]


def dynabarn_document(world: DynaBarnWorld) -> dict[str, Any]:
    """The world file's content (plain YAML types, rounded for a stable text)."""
    x, y, yaw = world.start
    length = world.reference.length_m
    rule, layout, robot = world.rule, world.layout, world.robot
    speeds = [c.speed_mps for c in world.crossings]
    return {
        "name": world.name,
        "map": f"maps/{world.name}.yaml",
        "wall_height": WALL_HEIGHT_M,
        "robots": [
            {"id": "r1", "x": _r(x), "y": _r(y), "yaw": _r(yaw, 6), "model": robot.world_ref}
        ],
        "movers": mover_entries(world),
        "benchmark": {
            "format": FORMAT,
            "protocol": PROTOCOL,
            "model": robot.name,
            "level": world.level,
            "seed": world.seed,
            "start": [_r(x), _r(y), _r(yaw, 6)],
            "goal": [_r(world.goal[0]), _r(world.goal[1])],
            "goal_tolerance_m": GOAL_TOLERANCE_M,
            "reference_path_length_m": _r(length),
            "optimal_time_s": _r(optimal_time(length, robot.max_linear_mps)),
            "time_limit_s": time_limit(robot.max_linear_mps),
            "top_speed_mps": robot.max_linear_mps,
            "footprint_radius_m": robot.footprint_radius_m,
            "fill_ratio": 0.0,
            "attempts": 1,
            "obstacles_mapped": False,
            "generator": {
                "method": "movers_across",
                "movers": rule.movers,
                "speed_mps": [min(speeds, default=0.0), max(speeds, default=0.0)],
                "max_speed_mps": rule.max_speed_mps,
                "radius_m": list(rule.radius_m),
                "slant_m": rule.slant_m,
                "cell_m": layout.cell_m,
                "field_cells": [layout.field_cols, layout.field_rows],
                "start_to_field_m": layout.start_to_field_m,
                "goal_distance_m": layout.goal_distance_m,
                "margin_m": layout.margin_m,
            },
            "difficulty": world.difficulty.to_json(),
            "reference_path": [[_r(px), _r(py)] for px, py in world.reference.points],
        },
    }


def write_dynabarn_world(world: DynaBarnWorld, folder: Path, *, header: str = "") -> Path:
    """Write the world file, its map YAML and its PGM (walls only) under ``folder``."""
    maps = folder / "maps"
    maps.mkdir(parents=True, exist_ok=True)
    pixels = np.where(world.walls, OCCUPIED_PX, FREE_PX).astype(np.uint8)
    (maps / f"{world.name}.pgm").write_bytes(encode_pgm(np.flipud(pixels)))
    (maps / f"{world.name}.yaml").write_text(
        map_yaml(f"{world.name}.pgm", world.layout.resolution_m, ORIGIN[0], ORIGIN[1])
    )
    comment = "".join(f"# {line}\n".replace("# \n", "#\n") for line in header.splitlines())
    doc = dynabarn_document(world)
    body = yaml.dump(doc, Dumper=_Dumper, sort_keys=False, default_flow_style=None)
    path = folder / f"{world.name}.yaml"
    path.write_text(comment + body)
    return path


def write_preview(path: Path, world: DynaBarnWorld) -> None:
    """A picture of the world: the walls, the movers' tracks, the reference path, the start
    and the goal."""
    from pnav.navbench.render import draw_world, write_world_png

    image = draw_world(
        world.walls,
        world.layout.resolution_m,
        ORIGIN,
        reference_path=world.reference.points,
        start=world.start[:2],
        goal=world.goal,
        goal_tolerance_m=GOAL_TOLERANCE_M,
        footprint_radius_m=world.robot.footprint_radius_m,
        inflation_m=world.inflation_m,
        movers=mover_specs(world),
    )
    write_world_png(path, image)


COLUMNS = (
    "world",
    "level",
    "seed",
    "movers",
    "speeds m/s",
    "radii m",
    "L_ref m",
    "OT s",
    "limit s",
)


def table_rows(worlds: Sequence[DynaBarnWorld]) -> list[list[str]]:
    rows = []
    for w in worlds:
        length, speed = w.reference.length_m, w.robot.max_linear_mps
        speeds = [c.speed_mps for c in w.crossings]
        radii = [c.radius_m for c in w.crossings]
        rows.append(
            [
                w.name,
                w.level,
                str(w.seed),
                str(len(w.crossings)),
                f"{min(speeds):.2f}-{max(speeds):.2f}",
                f"{min(radii):.2f}-{max(radii):.2f}",
                f"{length:.2f}",
                f"{optimal_time(length, speed):.2f}",
                f"{time_limit(speed):.0f}",
            ]
        )
    return rows


def dynabarn_suite_markdown(worlds: Sequence[DynaBarnWorld], command: str) -> str:
    from pnav.navbench.worlds_cli import markdown_table

    robot, layout = worlds[0].robot, worlds[0].layout
    used = dict.fromkeys(w.level for w in worlds)
    level_rows = [
        [lv, str(LEVELS[lv].movers), f"{LEVELS[lv].max_speed_mps}", f"{LEVELS[lv].radius_m}"]
        for lv in used
    ]
    return (
        "\n\n".join(
            [
                "# Benchmark worlds (dynamic BARN protocol)",
                "Generated, not drawn by hand: do not edit these files; generate them again. "
                "The protocol, the levels and the world file fields are in `docs/NAVBENCH.md` "
                "(*The dynamic BARN protocol*). Written by:",
                f"```sh\n{command}\n```",
                "The output does not depend on the machine: the same command writes the same "
                "bytes.",
                "## The protocol",
                f"- Robot: `{robot.name}` (top speed {robot.max_linear_mps} m/s, footprint "
                f"radius {robot.footprint_radius_m} m).\n"
                f"- BARN's corridor ({layout.width_m:.2f} m wide) with no standing obstacle: "
                "cylinders (the world file's `movers`) run back and forth on lines across it "
                f"over the {layout.field_rows * layout.cell_m:.1f} m of the field, each at its "
                f"own speed ({MIN_SPEED_MPS} m/s up to the level's top) and phase. The map the "
                "planner gets has the walls only; the lidar alone sees the movers.\n"
                f"- Start {layout.start_to_field_m} m below the field, goal "
                f"{layout.goal_distance_m} m straight ahead; success within "
                f"{GOAL_TOLERANCE_M} m of the goal, no collision (a mover touching the robot "
                f"counts), within the time limit ({time_limit(robot.max_linear_mps):.0f} s).",
                "## Levels",
                markdown_table(("level", "movers", "top speed m/s", "radius m"), level_rows),
                "## Worlds",
                "`speeds`, `radii`: the slowest and fastest, the smallest and largest mover; "
                "`L_ref`: reference path length; `OT`: optimal time at the robot's top speed; "
                "`limit`: the time limit.",
                markdown_table(COLUMNS, table_rows(worlds)),
            ]
        )
        + "\n"
    )

"""BARN-protocol worlds on disk, and their suite's SUITE.md.

The files are those of the default protocol (``pnav.navbench.worldfile``): ``D/N.yaml``,
``D/maps/N.{yaml,pgm}``, with three differences. The map holds the walls only; the field's
obstacles are the world file's ``obstacles`` (boxes covering the occupied cells exactly), so
the sim has them and the planner, given the map, does not. The robot entry names its
``model``. And the ``benchmark`` section says ``protocol: barn`` with BARN's goal tolerance
(1 m), its time limit for the model, and the model's top speed and footprint.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from pnav.navbench.barn import (
    GOAL_TOLERANCE_M,
    LEVELS,
    OBSTACLE_HEIGHT_M,
    POLYGON_MARGIN_M,
    PROTOCOL,
    WALL_HEIGHT_M,
    BarnWorld,
    time_limit,
)
from pnav.navbench.generator import ORIGIN
from pnav.navbench.metrics import optimal_time
from pnav.navbench.robots import RobotFit
from pnav.navbench.worldfile import FORMAT, FREE_PX, OCCUPIED_PX
from services.sim.mapserver import encode_pgm, map_yaml


def _r(value: float, digits: int = 4) -> float:
    return round(float(value), digits)


class _Inline(dict[str, Any]):
    """A mapping written on one line: an obstacle per line keeps the file readable."""


class _Dumper(yaml.SafeDumper):
    pass


_Dumper.add_representer(
    _Inline, lambda dumper, data: dumper.represent_mapping("tag:yaml.org,2002:map", data, True)
)


def obstacle_entries(world: BarnWorld) -> list[dict[str, Any]]:
    return [
        _Inline(
            {
                "name": f"field_{i:03d}",
                "type": "box",
                "x": box.x,
                "y": box.y,
                "size": [box.size_x, box.size_y, OBSTACLE_HEIGHT_M],
            }
        )
        for i, box in enumerate(world.boxes)
    ]


def barn_document(world: BarnWorld) -> dict[str, Any]:
    """The world file's content (plain YAML types, rounded for a stable text)."""
    x, y, yaw = world.start
    length = world.reference.length_m
    rule, layout, robot = world.rule, world.layout, world.robot
    return {
        "name": world.name,
        "map": f"maps/{world.name}.yaml",
        "wall_height": WALL_HEIGHT_M,
        "robots": [
            {"id": "r1", "x": _r(x), "y": _r(y), "yaw": _r(yaw, 6), "model": robot.world_ref}
        ],
        "obstacles": obstacle_entries(world),
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
            "fill_ratio": _r(world.fill_ratio),
            "attempts": world.attempts,
            "obstacles_mapped": False,
            "generator": {
                "method": "cellular_automaton",
                "fill_probability": rule.fill_probability,
                "smoothing_iterations": rule.smoothing_iterations,
                "fill_threshold": rule.fill_threshold,
                "clear_threshold": rule.clear_threshold,
                "cell_m": layout.cell_m,
                "field_cells": [layout.field_cols, layout.field_rows],
                "rows_below": layout.rows_below,
                "rows_above": layout.rows_above,
                "start_to_field_m": layout.start_to_field_m,
                "goal_distance_m": layout.goal_distance_m,
                "margin_m": layout.margin_m,
            },
            "difficulty": world.difficulty.to_json(),
            "reference_path": [[_r(px), _r(py)] for px, py in world.reference.points],
        },
    }


def write_barn_world(world: BarnWorld, folder: Path, *, header: str = "") -> Path:
    """Write the world file, its map YAML and its PGM (walls only) under ``folder``."""
    maps = folder / "maps"
    maps.mkdir(parents=True, exist_ok=True)
    pixels = np.where(world.walls, OCCUPIED_PX, FREE_PX).astype(np.uint8)
    (maps / f"{world.name}.pgm").write_bytes(encode_pgm(np.flipud(pixels)))
    (maps / f"{world.name}.yaml").write_text(
        map_yaml(f"{world.name}.pgm", world.layout.resolution_m, ORIGIN[0], ORIGIN[1])
    )
    comment = "".join(f"# {line}\n".replace("# \n", "#\n") for line in header.splitlines())
    body = yaml.dump(barn_document(world), Dumper=_Dumper, sort_keys=False, default_flow_style=None)
    path = folder / f"{world.name}.yaml"
    path.write_text(comment + body)
    return path


def write_preview(path: Path, world: BarnWorld) -> None:
    """A picture of the world as the sim has it (the obstacles drawn as occupied cells), the
    reference path, the start and the goal."""
    from pnav.navbench.render import draw_world, write_world_png

    image = draw_world(
        world.occupied,
        world.layout.resolution_m,
        ORIGIN,
        reference_path=world.reference.points,
        start=world.start[:2],
        goal=world.goal,
        goal_tolerance_m=GOAL_TOLERANCE_M,
        footprint_radius_m=world.robot.footprint_radius_m,
        inflation_m=world.inflation_m,
    )
    write_world_png(path, image)


COLUMNS = ("world", "level", "seed", "tries", "fill", "boxes", "L_ref m", "OT s", "limit s")


def table_rows(worlds: Sequence[BarnWorld]) -> list[list[str]]:
    rows = []
    for w in worlds:
        length, d, speed = w.reference.length_m, w.difficulty, w.robot.max_linear_mps
        rows.append(
            [
                w.name,
                w.level,
                str(w.seed),
                str(w.attempts),
                f"{w.fill_ratio:.3f}",
                str(len(w.boxes)),
                f"{length:.2f}",
                f"{optimal_time(length, speed):.2f}",
                f"{time_limit(speed):.0f}",
                f"{d.closest_obstacle_m:.3f}",
                f"{d.avg_visibility_m:.2f}",
                f"{d.dispersion:.2f}",
                f"{d.characteristic_dimension_m:.2f}",
                f"{d.tortuosity:.3f}",
            ]
        )
    return rows


def barn_suite_markdown(worlds: Sequence[BarnWorld], command: str) -> str:
    from pnav.navbench.worlds_cli import (
        MEAN_COLUMNS,
        METRIC_COLUMNS,
        level_means,
        markdown_table,
    )

    robot = worlds[0].robot
    used = dict.fromkeys(w.level for w in worlds)
    level_rows = [
        [lv, f"{LEVELS[lv].fill_probability}", str(LEVELS[lv].smoothing_iterations)] for lv in used
    ]
    layout = worlds[0].layout
    return (
        "\n\n".join(
            [
                "# Benchmark worlds (BARN protocol)",
                "Generated, not drawn by hand: do not edit these files; generate them again. "
                "The protocol, the levels and the world file fields are in `docs/NAVBENCH.md` "
                "(*The BARN protocol*). Written by:",
                f"```sh\n{command}\n```",
                "The output does not depend on the machine: the same command writes the same "
                "bytes (a model given as a file is named by its absolute path in the world "
                "files; a shipped model by its name).",
                "## The protocol",
                f"- Robot: `{robot.name}` (top speed {robot.max_linear_mps} m/s, footprint "
                f"radius {robot.footprint_radius_m} m); every world has a path for its disc "
                f"grown by {layout.margin_m} m{_polygon(robot)}.\n"
                f"- The obstacle field ({layout.field_cols} x {layout.field_rows} cells of "
                f"{layout.cell_m} m) is made of world obstacles (boxes): the map the planner "
                "gets has the walls only; the lidar alone sees the obstacles.\n"
                f"- Start {layout.start_to_field_m} m below the field, goal "
                f"{layout.goal_distance_m} m straight ahead; success within "
                f"{GOAL_TOLERANCE_M} m of the goal, no collision, within the time limit "
                f"({time_limit(robot.max_linear_mps):.0f} s: BARN's 100 s at 2 m/s, scaled "
                "to the robot's top speed).",
                "## Levels",
                markdown_table(("level", "fill probability", "smoothing steps"), level_rows),
                "## Means per level",
                markdown_table(MEAN_COLUMNS, level_means(worlds)),
                "## Worlds",
                "`fill`: occupied share of the field; `tries`: fields drawn until one had a "
                "path; `boxes`: world obstacles; `L_ref`: reference path length; `OT`: optimal "
                "time at the robot's top speed; `limit`: the time limit; then the difficulty "
                "metrics.",
                markdown_table((*COLUMNS, *METRIC_COLUMNS), table_rows(worlds)),
            ]
        )
        + "\n"
    )


def _polygon(robot: RobotFit) -> str:
    """What SUITE.md adds for a robot with a footprint polygon (the worlds' second check)."""
    if robot.footprint_polygon is None:
        return ""
    corners = ", ".join(f"({x:g}, {y:g})" for x, y in robot.footprint_polygon)
    return (
        f", along which its footprint polygon ({corners}; circumscribed radius "
        f"{robot.footprint.circumscribed_m:.3f} m) keeps {POLYGON_MARGIN_M} m from every "
        "obstacle, heading along each leg"
    )

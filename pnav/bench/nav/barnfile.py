"""BARN-protocol worlds on disk, and their suite's SUITE.md.

The files are those of the default protocol (``pnav.bench.nav.worldfile``): ``D/N.yaml``,
``D/maps/N.{yaml,pgm}``, with three differences. The map holds the walls only; the field's
obstacles are the world file's ``obstacles`` (boxes covering the occupied cells exactly), so
the sim has them and the planner, given the map, does not. The robot entry names its
``model``. And the ``benchmark`` section says ``protocol: barn`` with BARN's goal tolerance
(1 m), its time limit for the model, and the model's top speed and footprint.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeAlias

from pnav.bench.nav import suitefile
from pnav.bench.nav.barn import (
    GOAL_TOLERANCE_M,
    LEVELS,
    OBSTACLE_HEIGHT_M,
    POLYGON_MARGIN_M,
    PROTOCOL,
    WALL_HEIGHT_M,
    BarnWorld,
    time_limit,
)
from pnav.bench.nav.generator import ORIGIN
from pnav.bench.nav.robots import RobotFit
from pnav.bench.nav.scores import optimal_time
from pnav.bench.nav.search import BoolGrid
from services.sim.mover import MoverSpec

if TYPE_CHECKING:
    from pnav.bench.nav.dynabarn import DynaBarnWorld
    from pnav.bench.nav.render import Image

    # BARN's corridor, with standing obstacles or with movers
    CorridorWorld: TypeAlias = BarnWorld | DynaBarnWorld


def obstacle_entries(world: BarnWorld) -> list[dict[str, Any]]:
    return [
        suitefile.Inline(
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


def corridor_document(
    world: CorridorWorld,
    *,
    protocol: str,
    sim: dict[str, Any],
    generator: dict[str, Any],
    rows: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """A BARN-protocol world file's content (plain YAML types, rounded for a stable text):
    ``sim`` is what the sim has beyond the walls (its ``obstacles`` or ``movers``),
    ``generator`` the generator's own fields, ``rows`` the corridor's rows around the field
    where the generator has them."""
    length = world.reference.length_m
    layout, robot = world.layout, world.robot
    return {
        "name": world.name,
        "map": f"maps/{world.name}.yaml",
        "wall_height": WALL_HEIGHT_M,
        "robots": [suitefile.robot_entry(world, model=robot.world_ref)],
        **sim,
        "benchmark": {
            "format": suitefile.FORMAT,
            "protocol": protocol,
            "model": robot.name,
            **suitefile.route_fields(world, GOAL_TOLERANCE_M),
            "optimal_time_s": suitefile.rounded(optimal_time(length, robot.max_linear_mps)),
            "time_limit_s": time_limit(robot.max_linear_mps),
            "top_speed_mps": robot.max_linear_mps,
            "footprint_radius_m": robot.footprint_radius_m,
            "fill_ratio": suitefile.rounded(world.fill_ratio),
            "attempts": world.attempts,
            "obstacles_mapped": False,
            "generator": {
                **generator,
                **suitefile.field_fields(layout),
                **(rows or {}),
                "start_to_field_m": layout.start_to_field_m,
                "goal_distance_m": layout.goal_distance_m,
                "margin_m": layout.margin_m,
            },
            **suitefile.reference_fields(world),
        },
    }


def barn_document(world: BarnWorld) -> dict[str, Any]:
    """The world file's content (plain YAML types, rounded for a stable text)."""
    return corridor_document(
        world,
        protocol=PROTOCOL,
        sim={"obstacles": obstacle_entries(world)},
        generator=suitefile.automaton_fields(world.rule),
        rows={"rows_below": world.layout.rows_below, "rows_above": world.layout.rows_above},
    )


def write_barn_world(world: BarnWorld, folder: Path, *, header: str = "") -> Path:
    """Write the world file, its map YAML and its PGM (walls only) under ``folder``."""
    return suitefile.write_world_files(world, folder, world.walls, barn_document(world), header)


def draw_corridor(world: CorridorWorld, cells: BoolGrid, movers: Sequence[MoverSpec] = ()) -> Image:
    """A picture of a corridor world: ``cells`` occupied, the movers' tracks, the reference
    path, the start and the goal."""
    from pnav.bench.nav.render import draw_world

    return draw_world(
        cells,
        world.layout.resolution_m,
        ORIGIN,
        reference_path=world.reference.points,
        start=world.start[:2],
        goal=world.goal,
        goal_tolerance_m=GOAL_TOLERANCE_M,
        footprint_radius_m=world.robot.footprint_radius_m,
        inflation_m=world.inflation_m,
        movers=movers,
    )


def write_preview(path: Path, world: BarnWorld) -> None:
    """A picture of the world as the sim has it (the obstacles drawn as occupied cells), the
    reference path, the start and the goal."""
    from pnav.bench.nav.render import write_world_png

    write_world_png(path, draw_corridor(world, world.occupied))


COLUMNS = ("world", "level", "seed", "tries", "fill", "boxes", "L_ref m", "OT s", "limit s")


def table_rows(worlds: Sequence[BarnWorld]) -> list[list[str]]:
    rows = []
    for w in worlds:
        length, speed = w.reference.length_m, w.robot.max_linear_mps
        timing = [f"{length:.2f}", f"{optimal_time(length, speed):.2f}", f"{time_limit(speed):.0f}"]
        rows.append(suitefile.field_row(w, str(len(w.boxes)), *timing))
    return rows


def suite_tables(worlds: Sequence[BarnWorld]) -> str:
    return suitefile.field_tables(COLUMNS, table_rows(worlds), worlds)


def barn_suite_markdown(worlds: Sequence[BarnWorld], command: str) -> str:
    robot = worlds[0].robot
    used = dict.fromkeys(w.level for w in worlds)
    level_rows = [
        [lv, f"{LEVELS[lv].fill_probability}", str(LEVELS[lv].smoothing_iterations)] for lv in used
    ]
    layout = worlds[0].layout
    return suitefile.suite_page(
        "BARN protocol",
        "The protocol, the levels and the world file fields are in `docs/NAVBENCH.md` "
        "(*The BARN protocol*).",
        command,
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
        suitefile.markdown_table(("level", "fill probability", "smoothing steps"), level_rows),
        "## Means per level",
        suitefile.markdown_table(suitefile.MEAN_COLUMNS, suitefile.level_means(worlds)),
        "## Worlds",
        "`fill`: occupied share of the field; `tries`: fields drawn until one had a "
        "path; `boxes`: world obstacles; `L_ref`: reference path length; `OT`: optimal "
        "time at the robot's top speed; `limit`: the time limit; then the difficulty "
        "metrics.",
        suitefile.markdown_table((*COLUMNS, *suitefile.METRIC_COLUMNS), table_rows(worlds)),
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


SUITE_FILES = suitefile.SuiteFiles(
    write_barn_world, write_preview, barn_suite_markdown, suite_tables
)

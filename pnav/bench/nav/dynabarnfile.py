"""Dynamic BARN-protocol worlds on disk (``pnav.bench.nav.dynabarn``), and their SUITE.md.

The files are the BARN protocol's (``pnav.bench.nav.barnfile``): ``D/N.yaml``,
``D/maps/N.{yaml,pgm}`` (the walls only), the robot naming its ``model``. The world file's
``movers`` are the sim's moving obstacles (docs/SIM.md); it has no ``obstacles``. The
``benchmark`` section says ``protocol: dynabarn``, with BARN's goal tolerance and time limit
and the generator's level (how many movers, how fast).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pnav.bench.nav import suitefile
from pnav.bench.nav.barn import GOAL_TOLERANCE_M, time_limit
from pnav.bench.nav.barnfile import corridor_document, draw_corridor
from pnav.bench.nav.dynabarn import (
    LEVELS,
    MIN_SPEED_MPS,
    MOVER_HEIGHT_M,
    PROTOCOL,
    DynaBarnWorld,
)
from pnav.bench.nav.scores import optimal_time
from services.sim.mover import MoverSpec


def mover_entries(world: DynaBarnWorld) -> list[dict[str, Any]]:
    return [
        suitefile.Inline(
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
    rule = world.rule
    speeds = [c.speed_mps for c in world.crossings]
    return corridor_document(
        world,
        protocol=PROTOCOL,
        sim={"movers": mover_entries(world)},
        generator={
            "method": "movers_across",
            "movers": rule.movers,
            "speed_mps": [min(speeds, default=0.0), max(speeds, default=0.0)],
            "max_speed_mps": rule.max_speed_mps,
            "radius_m": list(rule.radius_m),
            "slant_m": rule.slant_m,
        },
    )


def write_dynabarn_world(world: DynaBarnWorld, folder: Path, *, header: str = "") -> Path:
    """Write the world file, its map YAML and its PGM (walls only) under ``folder``."""
    return suitefile.write_world_files(world, folder, world.walls, dynabarn_document(world), header)


def write_preview(path: Path, world: DynaBarnWorld) -> None:
    """A picture of the world: the walls, the movers' tracks, the reference path, the start
    and the goal."""
    from pnav.bench.nav.render import write_world_png

    write_world_png(path, draw_corridor(world, world.walls, mover_specs(world)))


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


def suite_tables(worlds: Sequence[DynaBarnWorld]) -> str:
    """What ``pnav worlds generate --protocol dynabarn`` prints: the worlds."""
    return suitefile.text_table(COLUMNS, table_rows(worlds))


def dynabarn_suite_markdown(worlds: Sequence[DynaBarnWorld], command: str) -> str:
    robot, layout = worlds[0].robot, worlds[0].layout
    used = dict.fromkeys(w.level for w in worlds)
    level_rows = [
        [lv, str(LEVELS[lv].movers), f"{LEVELS[lv].max_speed_mps}", f"{LEVELS[lv].radius_m}"]
        for lv in used
    ]
    return suitefile.suite_page(
        "dynamic BARN protocol",
        "The protocol, the levels and the world file fields are in `docs/NAVBENCH.md` "
        "(*The dynamic BARN protocol*).",
        command,
        "The output does not depend on the machine: the same command writes the same bytes.",
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
        suitefile.markdown_table(("level", "movers", "top speed m/s", "radius m"), level_rows),
        "## Worlds",
        "`speeds`, `radii`: the slowest and fastest, the smallest and largest mover; "
        "`L_ref`: reference path length; `OT`: optimal time at the robot's top speed; "
        "`limit`: the time limit.",
        suitefile.markdown_table(COLUMNS, table_rows(worlds)),
    )


SUITE_FILES = suitefile.SuiteFiles(
    write_dynabarn_world, write_preview, dynabarn_suite_markdown, suite_tables
)

"""What every protocol's world files share: the rounding that keeps their text stable, the
one-line mappings, the fields every ``benchmark`` section has, and writing a world's three
files (``D/N.yaml``, ``D/maps/N.{yaml,pgm}``; the layout is in ``pnav.bench.nav.worldfile``).

The protocol modules (``worldfile``, ``barnfile``, ``dynabarnfile``) say what differs: the
generator's fields, the world's obstacles or movers, the time limit and the robot.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Generic, TypeAlias, TypeVar

import numpy as np
import yaml

from pnav.bench.nav.generator import ORIGIN
from services.sim.mapserver import encode_pgm, map_yaml

if TYPE_CHECKING:
    from pnav.bench.nav.automaton import AutomatonRule
    from pnav.bench.nav.barn import BarnLayout, BarnWorld
    from pnav.bench.nav.difficulty import Difficulty
    from pnav.bench.nav.dynabarn import DynaBarnWorld
    from pnav.bench.nav.generator import GeneratedWorld, Layout
    from pnav.bench.nav.search import BoolGrid

    # a generated world of any protocol
    SuiteWorld: TypeAlias = GeneratedWorld | BarnWorld | DynaBarnWorld

W = TypeVar("W", bound="SuiteWorld")

FORMAT = 1
FREE_PX, OCCUPIED_PX = 254, 0  # as map_saver writes them


def rounded(value: float, digits: int = 4) -> float:
    """A number as the world files write it: rounded, so that the text does not depend on
    the last bits of the float arithmetic."""
    return round(float(value), digits)


class Inline(dict[str, Any]):
    """A mapping written on one line: an obstacle or mover per line keeps the file readable."""


class Dumper(yaml.SafeDumper):
    pass


Dumper.add_representer(
    Inline, lambda dumper, data: dumper.represent_mapping("tag:yaml.org,2002:map", data, True)
)


def robot_entry(world: SuiteWorld, **extra: Any) -> dict[str, Any]:
    """The world's one robot, ``r1``, at the start (``extra``: the model it names)."""
    x, y, yaw = world.start
    return {"id": "r1", "x": rounded(x), "y": rounded(y), "yaw": rounded(yaw, 6), **extra}


def route_fields(world: SuiteWorld, goal_tolerance_m: float) -> dict[str, Any]:
    """The ``benchmark`` fields that place the run: level, seed, start, goal, tolerance and
    the reference path's length."""
    x, y, yaw = world.start
    return {
        "level": world.level,
        "seed": world.seed,
        "start": [rounded(x), rounded(y), rounded(yaw, 6)],
        "goal": [rounded(world.goal[0]), rounded(world.goal[1])],
        "goal_tolerance_m": goal_tolerance_m,
        "reference_path_length_m": rounded(world.reference.length_m),
    }


def field_fields(layout: Layout | BarnLayout) -> dict[str, Any]:
    """The generator's field size, in every protocol's ``generator`` section."""
    return {"cell_m": layout.cell_m, "field_cells": [layout.field_cols, layout.field_rows]}


def automaton_fields(rule: AutomatonRule) -> dict[str, Any]:
    """The ``generator`` section's method and rule, for a field drawn by the automaton."""
    return {
        "method": "cellular_automaton",
        "fill_probability": rule.fill_probability,
        "smoothing_iterations": rule.smoothing_iterations,
        "fill_threshold": rule.fill_threshold,
        "clear_threshold": rule.clear_threshold,
    }


def reference_fields(world: SuiteWorld) -> dict[str, Any]:
    """The ``benchmark`` section's last fields: the difficulty and the reference path."""
    return {
        "difficulty": world.difficulty.to_json(),
        "reference_path": [[rounded(px), rounded(py)] for px, py in world.reference.points],
    }


def write_world_files(
    world: SuiteWorld, folder: Path, cells: BoolGrid, document: Mapping[str, Any], header: str
) -> Path:
    """Write the world file (``document`` under ``header`` as comment lines), its map YAML and
    its PGM (``cells``: the occupied ones, row 0 at the bottom) under ``folder``; the world
    file's path."""
    maps = folder / "maps"
    maps.mkdir(parents=True, exist_ok=True)
    pixels = np.where(cells, OCCUPIED_PX, FREE_PX).astype(np.uint8)
    (maps / f"{world.name}.pgm").write_bytes(encode_pgm(np.flipud(pixels)))
    (maps / f"{world.name}.yaml").write_text(
        map_yaml(f"{world.name}.pgm", world.layout.resolution_m, ORIGIN[0], ORIGIN[1])
    )
    comment = "".join(f"# {line}\n".replace("# \n", "#\n") for line in header.splitlines())
    body = yaml.dump(dict(document), Dumper=Dumper, sort_keys=False, default_flow_style=None)
    path = folder / f"{world.name}.yaml"
    path.write_text(comment + body)
    return path


METRIC_COLUMNS = ("closest m", "visib m", "dispers", "char m", "tortuos")
MEAN_COLUMNS = ("level (worlds)", "fill", "L_ref m", *METRIC_COLUMNS)


def metric_cells(d: Difficulty) -> list[str]:
    """A world's difficulty metrics, as the tables print them (``METRIC_COLUMNS``)."""
    return [
        f"{d.closest_obstacle_m:.3f}",
        f"{d.avg_visibility_m:.2f}",
        f"{d.dispersion:.2f}",
        f"{d.characteristic_dimension_m:.2f}",
        f"{d.tortuosity:.3f}",
    ]


def field_row(w: GeneratedWorld | BarnWorld, *cells: str) -> list[str]:
    """A row of the worlds' table for a world with a field of obstacles: its name, level,
    seed, tries and fill, the protocol's ``cells``, then the difficulty metrics."""
    head = [w.name, w.level, str(w.seed), str(w.attempts), f"{w.fill_ratio:.3f}"]
    return [*head, *cells, *metric_cells(w.difficulty)]


def level_means(worlds: Sequence[W]) -> list[list[str]]:
    """Per level: the mean fill, reference length and difficulty metrics."""
    rows = []
    for level in dict.fromkeys(w.level for w in worlds):
        group = [w for w in worlds if w.level == level]

        def mean(values: Sequence[float]) -> float:
            return sum(values) / len(values)

        d = [w.difficulty for w in group]
        rows.append(
            [
                f"{level} ({len(group)})",
                f"{mean([w.fill_ratio for w in group]):.3f}",
                f"{mean([w.reference.length_m for w in group]):.2f}",
                f"{mean([x.closest_obstacle_m for x in d]):.3f}",
                f"{mean([x.avg_visibility_m for x in d]):.2f}",
                f"{mean([x.dispersion for x in d]):.2f}",
                f"{mean([x.characteristic_dimension_m for x in d]):.2f}",
                f"{mean([x.tortuosity for x in d]):.3f}",
            ]
        )
    return rows


def text_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True))]
    lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    return "\n".join(line.rstrip() for line in lines)


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def suite_page(title: str, about: str, command: str, *sections: str) -> str:
    """A suite's SUITE.md: the title, what it is and where it is documented, the command that
    wrote it, then the protocol's own sections (each a paragraph, heading or table)."""
    return (
        "\n\n".join(
            [
                f"# Benchmark worlds ({title})",
                "Generated, not drawn by hand: do not edit these files; generate them again. "
                f"{about} Written by:",
                f"```sh\n{command}\n```",
                *sections,
            ]
        )
        + "\n"
    )


def field_tables(columns: Sequence[str], rows: Sequence[Sequence[str]], worlds: Sequence[W]) -> str:
    """What ``pnav worlds generate`` prints for worlds with a field of obstacles: the worlds
    (``columns``, ``rows``, then the difficulty metrics), then the means per level."""
    return "\n\n".join(
        [
            text_table((*columns, *METRIC_COLUMNS), rows),
            text_table(MEAN_COLUMNS, level_means(worlds)),
        ]
    )


@dataclass(frozen=True)
class SuiteFiles(Generic[W]):
    """How a protocol writes its suite: a world's files (``write(world, folder, header=)``),
    its preview picture, the SUITE.md and the tables ``pnav worlds generate`` prints."""

    write: Callable[..., Path]
    preview: Callable[[Path, W], object]
    markdown: Callable[[Sequence[W], str], str]
    tables: Callable[[Sequence[W]], str]

    def write_suite(
        self, worlds: Sequence[W], out: Path, *, command: str, header: str, png: bool
    ) -> None:
        """Write each world (with ``png`` its preview) and the SUITE.md; print the tables."""
        for world in worlds:
            self.write(world, out, header=header)
            if png:
                self.preview(out / "preview" / f"{world.name}.png", world)
        (out / "SUITE.md").write_text(self.markdown(worlds, command))
        print(self.tables(worlds))

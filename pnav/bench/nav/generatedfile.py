"""The default protocol's suite on disk: its SUITE.md, its tables and a preview per world.

The worlds' own files are pnav.bench.nav.worldfile's (which the pictures read back, so the
suite's page lives here, apart from it); BARN's suite is barnfile's, DynaBARN's dynabarnfile's.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from pnav.bench.nav import suitefile
from pnav.bench.nav.generator import LEVELS, GeneratedWorld
from pnav.bench.nav.scores import default_time_limit, optimal_time
from pnav.bench.nav.worldfile import write_world

COLUMNS = ("world", "level", "seed", "tries", "fill", "L_ref m", "OT s", "limit s")


def table_rows(worlds: Sequence[GeneratedWorld]) -> list[list[str]]:
    rows = []
    for w in worlds:
        length = w.reference.length_m
        timing = [f"{optimal_time(length):.1f}", f"{default_time_limit(length):.0f}"]
        rows.append(suitefile.field_row(w, f"{length:.2f}", *timing))
    return rows


def suite_tables(worlds: Sequence[GeneratedWorld]) -> str:
    return suitefile.field_tables(COLUMNS, table_rows(worlds), worlds)


def write_preview(path: Path, world: GeneratedWorld) -> None:
    """A picture of the freshly generated world: map, reference path, start and goal."""
    from pnav.bench.nav.render import draw_generated, write_world_png

    write_world_png(path, draw_generated(world))


def suite_markdown(worlds: Sequence[GeneratedWorld], command: str) -> str:
    used = dict.fromkeys(w.level for w in worlds)
    level_rows = [
        [
            level,
            f"{LEVELS[level].fill_probability}",
            str(LEVELS[level].smoothing_iterations),
            str(LEVELS[level].fill_threshold),
            str(LEVELS[level].clear_threshold),
        ]
        for level in used
    ]
    return suitefile.suite_page(
        "BARN-style",
        "The method, the levels, the metrics and the world file fields are in `docs/NAVBENCH.md`.",
        command,
        "`python -m pnav.bench.nav.worlds_cli generate ...` takes the same options. The "
        "output does not depend on the machine: the same command writes the same bytes.",
        "## Levels",
        suitefile.markdown_table(
            ("level", "fill probability", "smoothing steps", "fill if >=", "clear if <="),
            level_rows,
        ),
        "## Means per level",
        suitefile.markdown_table(suitefile.MEAN_COLUMNS, suitefile.level_means(worlds)),
        "## Worlds",
        "`fill`: occupied share of the field; `tries`: fields drawn until one had a path; "
        "`L_ref`: reference path length; `OT`: optimal time at 0.22 m/s; `limit`: the "
        "suggested time limit (8 OT, rounded up to 10 s); then the difficulty metrics.",
        suitefile.markdown_table((*COLUMNS, *suitefile.METRIC_COLUMNS), table_rows(worlds)),
    )


SUITE_FILES = suitefile.SuiteFiles(write_world, write_preview, suite_markdown, suite_tables)

"""BARN-style worlds: a cellular-automaton obstacle field between a start zone and a goal zone.

After Perille et al. 2020 ("Benchmarking Metric Ground Navigation", arXiv 2008.13315), scaled
to a TurtleBot3 Burger. The map, in automaton cells of ``cell_m`` (0.15 m, BARN's size)::

    +--------------------------------+   wall all round (one cell thick)
    |           goal zone            |   ``zone_rows`` free rows; the goal in the middle
    |################################|
    |##  obstacle field (automaton) ##|   ``field_rows`` x ``field_cols`` cells
    |################################|
    |           start zone           |   the robot starts here, facing the field
    +--------------------------------+

The field's left and right sides are the walls, so the only way to the goal is through it.
Each cell becomes ``cell_m / resolution_m`` x ``cell_m / resolution_m`` map pixels. A world is
kept only if the robot fits through: its disc grown by ``margin_m`` (the planner's own
inflation margin) must find a path from start to goal; otherwise the field is drawn again from
the same random stream, so a (level, seed) pair always gives the same world.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from pnav.navbench.automaton import AutomatonRule, BoolGrid, grow_field
from pnav.navbench.difficulty import Difficulty, measure
from pnav.navbench.search import Point, ReferencePath, reference_path
from services.sim.robot import BURGER

# Fill probability grows and smoothing shrinks with the level: more clutter, and clutter left
# in small scattered pieces rather than merged into a few blobs with open space between.
LEVELS: dict[str, AutomatonRule] = {
    "easy": AutomatonRule(fill_probability=0.20, smoothing_iterations=3),
    "medium": AutomatonRule(fill_probability=0.25, smoothing_iterations=3),
    "hard": AutomatonRule(fill_probability=0.30, smoothing_iterations=2),
}
SEEDS_PER_SUITE = 1000  # world i of a suite drawn with --seed S uses seed S * 1000 + i


@dataclass(frozen=True)
class Layout:
    cell_m: float = 0.15
    resolution_m: float = 0.05
    field_cols: int = 30
    field_rows: int = 30
    zone_rows: int = 6
    footprint_radius_m: float = BURGER.footprint_radius_m
    margin_m: float = 0.05

    def __post_init__(self) -> None:
        if abs(self.scale * self.resolution_m - self.cell_m) > 1e-9:
            raise ValueError("cell_m must be a whole number of map pixels (resolution_m)")
        if self.margin_m < self.resolution_m * math.sqrt(0.5):
            # below half a pixel's diagonal, a traversable pixel no longer proves that the
            # robot fits everywhere inside it (see search.py)
            raise ValueError("margin_m must be at least half a map pixel's diagonal")
        if self.zone_rows < 3 or self.field_rows < 1 or self.field_cols < 3:
            raise ValueError("the zones need 3 rows, the field at least 1 x 3 cells")

    @property
    def scale(self) -> int:
        """Map pixels per automaton cell, along each side."""
        return round(self.cell_m / self.resolution_m)

    @property
    def width_m(self) -> float:
        return (self.field_cols + 2) * self.cell_m

    @property
    def height_m(self) -> float:
        return (self.field_rows + 2 * self.zone_rows + 2) * self.cell_m

    @property
    def inflation_m(self) -> float:
        return self.footprint_radius_m + self.margin_m

    @property
    def start(self) -> tuple[float, float, float]:
        """(x, y, yaw): the middle of the start zone, facing the field (+y)."""
        return self.width_m / 2.0, self.cell_m * (1 + self.zone_rows / 2.0), math.pi / 2.0

    @property
    def goal(self) -> Point:
        return self.width_m / 2.0, self.height_m - self.cell_m * (1 + self.zone_rows / 2.0)

    @property
    def field_y(self) -> tuple[float, float]:
        low = self.cell_m * (1 + self.zone_rows)
        return low, low + self.field_rows * self.cell_m


DEFAULT_LAYOUT = Layout()
ORIGIN: Point = (0.0, 0.0)  # the map's lower-left corner is the world's (0, 0)


@dataclass(frozen=True, eq=False)  # eq would compare the numpy grid: ambiguous
class GeneratedWorld:
    name: str
    level: str
    seed: int
    attempts: int  # fields drawn until one had a path (the rejected ones included)
    rule: AutomatonRule
    layout: Layout
    occupied: BoolGrid = field(repr=False)  # map pixels [row, col], row 0 at the bottom
    fill_ratio: float  # occupied share of the field's cells
    reference: ReferencePath
    difficulty: Difficulty

    @property
    def start(self) -> tuple[float, float, float]:
        return self.layout.start

    @property
    def goal(self) -> Point:
        return self.layout.goal


def rasterize(cells: BoolGrid, layout: Layout) -> BoolGrid:
    """The map pixels (row 0 at the bottom) of a field of automaton cells, with the walls and
    the two free zones around it."""
    rows = layout.field_rows + 2 * layout.zone_rows + 2
    grid = np.zeros((rows, layout.field_cols + 2), dtype=bool)
    grid[[0, -1], :] = True
    grid[:, [0, -1]] = True
    low = 1 + layout.zone_rows
    grid[low : low + layout.field_rows, 1:-1] = cells
    pixels: BoolGrid = np.kron(grid, np.ones((layout.scale, layout.scale), dtype=bool))
    return pixels


def level_rule(level: str) -> AutomatonRule:
    try:
        return LEVELS[level]
    except KeyError:
        raise ValueError(f"unknown level {level!r}; known: {', '.join(LEVELS)}") from None


def generate_world(
    level: str,
    seed: int,
    *,
    name: str | None = None,
    layout: Layout = DEFAULT_LAYOUT,
    max_attempts: int = 5000,
) -> GeneratedWorld:
    """The world of ``level`` drawn with ``seed``: the first field of that random stream
    through which the robot finds a path. Raises RuntimeError after ``max_attempts``."""
    rule = level_rule(level)
    if seed < 0:
        raise ValueError(f"seed must not be negative, got {seed}")
    # the level is mixed into the stream: seed 7 of two levels are unrelated worlds
    rng = np.random.default_rng([seed, zlib.crc32(level.encode())])
    x0, y0, _ = layout.start
    for attempt in range(1, max_attempts + 1):
        cells = grow_field(rng, layout.field_rows, layout.field_cols, rule)
        occupied = rasterize(cells, layout)
        ref = reference_path(
            occupied, layout.resolution_m, ORIGIN, (x0, y0), layout.goal, layout.inflation_m
        )
        if ref is not None:
            return GeneratedWorld(
                name=name or f"barn_{level}_s{seed}",
                level=level,
                seed=seed,
                attempts=attempt,
                rule=rule,
                layout=layout,
                occupied=occupied,
                fill_ratio=float(cells.mean()),
                reference=ref,
                difficulty=measure(
                    occupied, layout.resolution_m, ORIGIN, ref.points, layout.field_y
                ),
            )
    raise RuntimeError(f"no passable {level} world in {max_attempts} attempts (seed {seed})")


def suite_seed(base_seed: int, index: int) -> int:
    return base_seed * SEEDS_PER_SUITE + index


def generate_suite(
    levels: Sequence[str], count: int, base_seed: int, *, layout: Layout = DEFAULT_LAYOUT
) -> list[GeneratedWorld]:
    """``count`` worlds per level, named ``barn_<level>_<index>`` (index from 000)."""
    if not 0 < count <= SEEDS_PER_SUITE:
        raise ValueError(f"count must be within 1..{SEEDS_PER_SUITE}, got {count}")
    for level in levels:
        level_rule(level)  # fail before any work on a typo
    return [
        generate_world(level, suite_seed(base_seed, i), name=f"barn_{level}_{i:03d}", layout=layout)
        for level in levels
        for i in range(count)
    ]

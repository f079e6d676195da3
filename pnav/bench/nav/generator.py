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
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol, TypeVar

import numpy as np

from pnav.bench.nav.automaton import AutomatonRule, BoolGrid, grow_field
from pnav.bench.nav.difficulty import Difficulty, measure
from pnav.bench.nav.search import Point, ReferencePath, reference_path
from services.sim.robot import BURGER

# Fill probability grows and smoothing shrinks with the level: more clutter, and clutter left
# in small scattered pieces rather than merged into a few blobs with open space between.
LEVELS: dict[str, AutomatonRule] = {
    "easy": AutomatonRule(fill_probability=0.20, smoothing_iterations=3),
    "medium": AutomatonRule(fill_probability=0.25, smoothing_iterations=3),
    "hard": AutomatonRule(fill_probability=0.30, smoothing_iterations=2),
}
SEEDS_PER_SUITE = 1000  # world i of a suite drawn with --seed S uses seed S * 1000 + i

T = TypeVar("T")
W = TypeVar("W")


def known_level(levels: Mapping[str, T], level: str, error: type[Exception]) -> T:
    """A protocol's rule for ``level``; ``error`` (the protocol's) names the known ones."""
    try:
        return levels[level]
    except KeyError:
        raise error(f"unknown level {level!r}; known: {', '.join(levels)}") from None


def world_stream(seed: int, stream: str, error: type[Exception]) -> np.random.Generator:
    """The random stream world ``seed`` is drawn from, ``error`` for a negative seed.
    ``stream`` (the level, or protocol/level) is mixed in: seed 7 of two levels, or of two
    protocols, are unrelated worlds."""
    if seed < 0:
        raise error(f"seed must not be negative, got {seed}")
    return np.random.default_rng([seed, zlib.crc32(stream.encode())])


def draw_suite(
    levels: Sequence[str],
    count: int,
    base_seed: int,
    draw: Callable[[str, int, str], W],
    check: Callable[[str], object],
    error: type[Exception],
    prefix: str,
) -> list[W]:
    """``count`` worlds per level, world i drawn (``draw(level, seed, name)``) with seed
    ``suite_seed(base_seed, i)`` and named ``<prefix>_<level>_<i>`` (i from 000)."""
    if not 0 < count <= SEEDS_PER_SUITE:
        raise error(f"count must be within 1..{SEEDS_PER_SUITE}, got {count}")
    for level in levels:
        check(level)  # fail before any work on a typo
    return [
        draw(level, suite_seed(base_seed, i), f"{prefix}_{level}_{i:03d}")
        for level in levels
        for i in range(count)
    ]


class _Placed(Protocol):
    @property
    def start(self) -> tuple[float, float, float]: ...
    @property
    def goal(self) -> Point: ...


class OnLayout:
    """A generated world's start and goal: its layout's."""

    layout: _Placed

    @property
    def start(self) -> tuple[float, float, float]:
        return self.layout.start

    @property
    def goal(self) -> Point:
        return self.layout.goal


class FieldCells:
    """A layout whose field of square cells is drawn in map pixels, a wall cell each side."""

    cell_m: float
    resolution_m: float
    field_cols: int
    margin_m: float

    def check_pixels(self, error: type[Exception]) -> None:
        """``error`` (the protocol's) unless a cell is whole pixels and the margin enough."""
        if abs(self.scale * self.resolution_m - self.cell_m) > 1e-9:
            raise error("cell_m must be a whole number of map pixels (resolution_m)")
        if self.margin_m < self.resolution_m * math.sqrt(0.5):
            # below half a pixel's diagonal, a traversable pixel no longer proves that the
            # robot fits everywhere inside it (see search.py)
            raise error("margin_m must be at least half a map pixel's diagonal")

    @property
    def scale(self) -> int:
        """Map pixels per automaton cell, along each side."""
        return round(self.cell_m / self.resolution_m)

    @property
    def width_m(self) -> float:
        return (self.field_cols + 2) * self.cell_m


@dataclass(frozen=True)
class Layout(FieldCells):
    cell_m: float = 0.15
    resolution_m: float = 0.05
    field_cols: int = 30
    field_rows: int = 30
    zone_rows: int = 6
    footprint_radius_m: float = BURGER.footprint_radius_m
    margin_m: float = 0.05

    def __post_init__(self) -> None:
        self.check_pixels(ValueError)
        if self.zone_rows < 3 or self.field_rows < 1 or self.field_cols < 3:
            raise ValueError("the zones need 3 rows, the field at least 1 x 3 cells")

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
class GeneratedWorld(OnLayout):
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
    return known_level(LEVELS, level, ValueError)


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
    rng = world_stream(seed, level, ValueError)
    found = first_passable(
        rng, rule, layout, lambda cells: rasterize(cells, layout), layout.inflation_m, max_attempts
    )
    if found is not None:
        return GeneratedWorld(
            name=name or f"barn_{level}_s{seed}",
            level=level,
            seed=seed,
            attempts=found.attempt,
            rule=rule,
            layout=layout,
            occupied=found.occupied,
            fill_ratio=found.fill_ratio,
            reference=found.reference,
            difficulty=found.difficulty,
        )
    raise RuntimeError(f"no passable {level} world in {max_attempts} attempts (seed {seed})")


class _FieldPlace(Protocol):
    @property
    def field_rows(self) -> int: ...
    @property
    def field_cols(self) -> int: ...
    @property
    def resolution_m(self) -> float: ...
    @property
    def start(self) -> tuple[float, float, float]: ...
    @property
    def goal(self) -> Point: ...
    @property
    def field_y(self) -> tuple[float, float]: ...


@dataclass(frozen=True, eq=False)  # eq would compare the numpy grids: ambiguous
class Passable:
    """A field drawn with a path through it: which draw it was, its cells, the map pixels
    the robot meets, the reference path and its difficulty."""

    attempt: int
    cells: BoolGrid = field(repr=False)
    occupied: BoolGrid = field(repr=False)
    reference: ReferencePath
    difficulty: Difficulty

    @property
    def fill_ratio(self) -> float:
        return float(self.cells.mean())


def first_passable(
    rng: np.random.Generator,
    rule: AutomatonRule,
    layout: _FieldPlace,
    pixels: Callable[[BoolGrid], BoolGrid],
    inflation_m: float,
    max_attempts: int,
    fits: Callable[[BoolGrid, ReferencePath], bool] = lambda occupied, ref: True,
) -> Passable | None:
    """The first field of ``rng`` (``pixels``: its map pixels) through which a disc inflated
    by ``inflation_m`` finds a path that ``fits`` also accepts; None after ``max_attempts``."""
    x0, y0, _ = layout.start
    for attempt in range(1, max_attempts + 1):
        cells = grow_field(rng, layout.field_rows, layout.field_cols, rule)
        occupied = pixels(cells)
        ref = reference_path(
            occupied, layout.resolution_m, ORIGIN, (x0, y0), layout.goal, inflation_m
        )
        if ref is not None and fits(occupied, ref):
            res = layout.resolution_m
            difficulty = measure(occupied, res, ORIGIN, ref.points, layout.field_y)
            return Passable(attempt, cells, occupied, ref, difficulty)
    return None


def suite_seed(base_seed: int, index: int) -> int:
    return base_seed * SEEDS_PER_SUITE + index


def generate_suite(
    levels: Sequence[str], count: int, base_seed: int, *, layout: Layout = DEFAULT_LAYOUT
) -> list[GeneratedWorld]:
    """``count`` worlds per level, named ``barn_<level>_<index>`` (index from 000)."""

    def draw(level: str, seed: int, name: str) -> GeneratedWorld:
        return generate_world(level, seed, name=name, layout=layout)

    return draw_suite(levels, count, base_seed, draw, level_rule, ValueError, "barn")

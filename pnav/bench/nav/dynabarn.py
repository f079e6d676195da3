"""The dynamic BARN protocol: BARN's corridor crossed by moving obstacles (DynaBARN-like).

DynaBARN (Nair et al., 2022) added worlds to the BARN Challenge in which obstacles move
across the robot's way instead of standing in it. Here the layout is the BARN protocol's
(``pnav.bench.nav.barn``: walls all round, start 2 m below the field, goal 10 m straight
ahead, success within 1 m, BARN's time limit for the robot's top speed), the field holds no
standing obstacle, and ``movers`` cylinders run back and forth on lines across the corridor
(each end at a height of the field drawn on its own, so a line may slant), at 0.1 to 1.0 m/s,
each at a random phase. The movers are the sim's (services/sim/mover.py): the map the
planner gets has the walls only and the lidar alone sees them. The levels differ in how many
movers there are and how fast the fastest may go.

A world is drawn from a random stream seeded by (seed, protocol, level): the same command
writes the same worlds, byte for byte.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from common.errors import UsageError
from pnav.bench.nav.automaton import BoolGrid
from pnav.bench.nav.barn import DEFAULT_LAYOUT, BarnLayout, InCorridor, wall_pixels
from pnav.bench.nav.difficulty import Difficulty, measure
from pnav.bench.nav.generator import ORIGIN, draw_suite, known_level, world_stream
from pnav.bench.nav.robots import RobotFit
from pnav.bench.nav.search import ReferencePath, reference_path

PROTOCOL = "dynabarn"
MOVER_HEIGHT_M = 1.0  # above any lidar's mount: every model sees them
# the slowest any mover goes, m/s (DynaBARN's obstacles: 0.1 to 1.0 m/s)
MIN_SPEED_MPS = 0.1
# how far from the side walls a mover's line ends: it never grazes them
WALL_GAP_M = 0.05


@dataclass(frozen=True)
class DynaLevel:
    movers: int
    max_speed_mps: float
    radius_m: tuple[float, float] = (0.15, 0.25)  # each mover's radius, drawn within
    slant_m: float = 0.5  # each end of a line within +- this of the line's middle height


LEVELS: dict[str, DynaLevel] = {
    "easy": DynaLevel(movers=3, max_speed_mps=0.5),
    "medium": DynaLevel(movers=5, max_speed_mps=0.75),
    "hard": DynaLevel(movers=7, max_speed_mps=1.0),
}


@dataclass(frozen=True)
class Crossing:
    """One mover: a cylinder running back and forth from ``a`` to ``b``."""

    name: str
    radius_m: float
    a: tuple[float, float]
    b: tuple[float, float]
    speed_mps: float
    offset_m: float


@dataclass(frozen=True, eq=False)  # eq would compare the numpy grid: ambiguous
class DynaBarnWorld(InCorridor):
    name: str
    level: str
    seed: int
    rule: DynaLevel
    layout: BarnLayout
    robot: RobotFit
    walls: BoolGrid = field(repr=False)  # the map the planner gets, and all the sim has
    crossings: tuple[Crossing, ...]
    reference: ReferencePath
    difficulty: Difficulty
    attempts: int = 1
    fill_ratio: float = 0.0  # no standing obstacle in the field


def level_rule(level: str) -> DynaLevel:
    return known_level(LEVELS, level, UsageError)


def _crossings(rng: np.random.Generator, rule: DynaLevel, layout: BarnLayout) -> list[Crossing]:
    low, high = layout.field_y
    inner = (layout.cell_m, layout.width_m - layout.cell_m)  # between the side walls
    out = []
    for i in range(rule.movers):
        radius = round(float(rng.uniform(*rule.radius_m)), 3)
        # the lines' middles spread evenly over the field, each moved within its share
        share = (high - low) / rule.movers
        middle = low + share * (i + float(rng.uniform(0.25, 0.75)))
        ends = [
            float(np.clip(middle + rng.uniform(-rule.slant_m, rule.slant_m), low, high))
            for _ in range(2)
        ]
        x0, x1 = inner[0] + radius + WALL_GAP_M, inner[1] - radius - WALL_GAP_M
        a, b = (x0, ends[0]), (x1, ends[1])
        if rng.uniform() < 0.5:  # which side it sets off from
            a, b = b, a
        length = float(np.hypot(b[0] - a[0], b[1] - a[1]))
        out.append(
            Crossing(
                name=f"mover_{i:02d}",
                radius_m=radius,
                a=(round(a[0], 3), round(a[1], 3)),
                b=(round(b[0], 3), round(b[1], 3)),
                speed_mps=round(float(rng.uniform(MIN_SPEED_MPS, rule.max_speed_mps)), 3),
                offset_m=round(float(rng.uniform(0.0, 2.0 * length)), 3),
            )
        )
    return out


def generate_dynabarn_world(
    level: str,
    seed: int,
    robot: RobotFit,
    *,
    name: str | None = None,
    layout: BarnLayout = DEFAULT_LAYOUT,
) -> DynaBarnWorld:
    """The dynamic world of ``level`` drawn with ``seed`` for ``robot``. The same (level,
    seed, robot) always gives the same world."""
    rule = level_rule(level)
    rng = world_stream(seed, f"{PROTOCOL}/{level}", UsageError)
    walls = wall_pixels(layout)
    x0, y0, _ = layout.start
    inflation = robot.footprint_radius_m + layout.margin_m
    ref = reference_path(walls, layout.resolution_m, ORIGIN, (x0, y0), layout.goal, inflation)
    if ref is None:
        raise UsageError(f"{robot.name} (footprint {robot.footprint_radius_m} m) does not fit")
    return DynaBarnWorld(
        name=name or f"dynabarn_{level}_s{seed}",
        level=level,
        seed=seed,
        rule=rule,
        layout=layout,
        robot=robot,
        walls=walls,
        crossings=tuple(_crossings(rng, rule, layout)),
        reference=ref,
        difficulty=measure(walls, layout.resolution_m, ORIGIN, ref.points, layout.field_y),
    )


def generate_dynabarn_suite(
    levels: Sequence[str], count: int, base_seed: int, robot: RobotFit
) -> list[DynaBarnWorld]:
    """``count`` worlds per level, named ``dynabarn_<level>_<index>``."""

    def draw(level: str, seed: int, name: str) -> DynaBarnWorld:
        return generate_dynabarn_world(level, seed, robot, name=name)

    return draw_suite(levels, count, base_seed, draw, level_rule, UsageError, "dynabarn")

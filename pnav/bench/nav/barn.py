"""The BARN protocol: worlds laid out and scored as the BARN Challenge runs its robot.

As the challenge (Perille et al., SSRR 2020; the ICRA BARN Challenge's ``run.py``): the
obstacle field is a 30 x 30 grid of 0.15 m cells drawn by the cellular automaton, the robot
starts 2 m below the field and its goal lies 10 m straight ahead of the start; the
navigation stack gets **no map of the obstacles** (here: they are world obstacles, absent
from the map the planner is given; the lidar alone sees them); a run succeeds when the robot
comes within 1 m of the goal without a collision within the time limit, 100 s for the
challenge's Jackal (top speed 2 m/s). The layout, in cells of ``cell_m``::

    +--------------------------------+   wall all round (one cell thick, in the map)
    |                                |   ``beyond_goal_m`` of free floor past the goal
    |             goal               |
    |                                |   3.5 m of free floor (goal - field)
    |################################|
    |##  obstacle field (automaton) ##|   30 x 30 cells: world obstacles, not in the map
    |################################|
    |                                |   2 m (start - field)
    |             start              |
    +--------------------------------+

The side walls run the whole length, so the only way to the goal is through the field. A
world is kept only if the model's disc, grown by the planner's margin, finds a path (the
same check as the default protocol, ``pnav.bench.nav.generator``) and, for a model with a
footprint polygon (the Jackal's box), the polygon keeps 2 cm from every obstacle along that
path heading along each leg (:func:`fits`), else the field is drawn again from the same
random stream.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from common.collision import collides_on_grid, path_poses
from common.errors import UsageError
from pnav.bench.nav.automaton import AutomatonRule, BoolGrid
from pnav.bench.nav.difficulty import Difficulty
from pnav.bench.nav.generator import (
    ORIGIN,
    FieldCells,
    OnLayout,
    draw_suite,
    first_passable,
    known_level,
    world_stream,
)
from pnav.bench.nav.robots import RobotFit
from pnav.bench.nav.search import Point, ReferencePath

PROTOCOL = "barn"
# what a footprint polygon keeps from the obstacles along the reference path (as the
# planner's path check keeps, services/planner/fit.py), m
POLYGON_MARGIN_M = 0.02
BARN_TOP_SPEED_MPS = 2.0  # the Jackal's, as the challenge computes OT
BARN_TIME_LIMIT_S = 100.0  # the challenge's, for that speed
GOAL_TOLERANCE_M = 1.0
OBSTACLE_HEIGHT_M = 1.0  # above any lidar's mount: every model sees them
WALL_HEIGHT_M = 1.0

# The Jackal's disc is twice the Burger's: a field drawn with the default protocol's hard
# rule (generator.LEVELS) lets it through once in 50 draws, and the few kept are no harder
# than the medium ones (only fields with room for it pass). So the BARN protocol fills less
# at each level; the levels still differ in every difficulty metric.
LEVELS: dict[str, AutomatonRule] = {
    "easy": AutomatonRule(fill_probability=0.15, smoothing_iterations=2),
    "medium": AutomatonRule(fill_probability=0.20, smoothing_iterations=2),
    "hard": AutomatonRule(fill_probability=0.25, smoothing_iterations=2),
}


@dataclass(frozen=True)
class BarnLayout(FieldCells):
    cell_m: float = 0.15
    resolution_m: float = 0.05
    field_cols: int = 30
    field_rows: int = 30
    rows_below: int = 17  # free rows between the bottom wall and the field
    start_to_field_m: float = 2.0
    goal_distance_m: float = 10.0
    beyond_goal_m: float = 1.0
    margin_m: float = 0.05  # the planner's inflation margin, as in the default protocol

    def __post_init__(self) -> None:
        self.check_pixels(UsageError)
        if self.start[1] <= self.cell_m or self.goal[1] <= self.field_y[1]:
            raise UsageError("the start must lie on the map and the goal beyond the field")

    @property
    def rows_above(self) -> int:
        """Free rows between the field and the top wall: to the goal and past it."""
        room = self.goal[1] + self.beyond_goal_m - self.field_y[1]
        return math.ceil(room / self.cell_m - 1e-9)

    @property
    def height_m(self) -> float:
        return (self.rows_below + self.field_rows + self.rows_above + 2) * self.cell_m

    @property
    def field_y(self) -> tuple[float, float]:
        low = (1 + self.rows_below) * self.cell_m
        return low, low + self.field_rows * self.cell_m

    @property
    def start(self) -> tuple[float, float, float]:
        """(x, y, yaw): below the field's middle, facing it (+y)."""
        return self.width_m / 2.0, self.field_y[0] - self.start_to_field_m, math.pi / 2.0

    @property
    def goal(self) -> Point:
        x, y, _ = self.start
        return x, y + self.goal_distance_m


DEFAULT_LAYOUT = BarnLayout()


@dataclass(frozen=True)
class Box:
    """A world obstacle covering whole field cells: centre (m) and full extents (m)."""

    x: float
    y: float
    size_x: float
    size_y: float


class InCorridor(OnLayout):
    """A world of BARN's corridor made for a robot: what its path was checked for."""

    layout: BarnLayout
    robot: RobotFit

    @property
    def inflation_m(self) -> float:
        return self.robot.footprint_radius_m + self.layout.margin_m


@dataclass(frozen=True, eq=False)  # eq would compare the numpy grids: ambiguous
class BarnWorld(InCorridor):
    name: str
    level: str
    seed: int
    attempts: int
    rule: AutomatonRule
    layout: BarnLayout
    robot: RobotFit
    walls: BoolGrid = field(repr=False)  # the map the planner gets: walls only
    occupied: BoolGrid = field(repr=False)  # what the sim has: walls and field obstacles
    boxes: tuple[Box, ...]
    fill_ratio: float
    reference: ReferencePath
    difficulty: Difficulty


def level_rule(level: str) -> AutomatonRule:
    return known_level(LEVELS, level, UsageError)


def time_limit(top_speed_mps: float) -> float:
    """BARN's 100 s, in the robot's own driving time: scaled by 2 m/s over its top speed
    (100 s for the Jackal), rounded up to whole 10 s."""
    if top_speed_mps <= 0:
        raise UsageError(f"the top speed must be positive, got {top_speed_mps}")
    return 10.0 * math.ceil(BARN_TIME_LIMIT_S * BARN_TOP_SPEED_MPS / top_speed_mps / 10 - 1e-9)


def wall_pixels(layout: BarnLayout) -> BoolGrid:
    """The map: a one-cell wall all round, free inside (row 0 at the bottom)."""
    rows = layout.rows_below + layout.field_rows + layout.rows_above + 2
    grid = np.zeros((rows, layout.field_cols + 2), dtype=bool)
    grid[[0, -1], :] = True
    grid[:, [0, -1]] = True
    pixels: BoolGrid = np.kron(grid, np.ones((layout.scale, layout.scale), dtype=bool))
    return pixels


def field_pixels(cells: BoolGrid, layout: BarnLayout) -> BoolGrid:
    """The walls and the field's occupied cells, as map pixels: what the robot meets."""
    rows = layout.rows_below + layout.field_rows + layout.rows_above + 2
    grid = np.zeros((rows, layout.field_cols + 2), dtype=bool)
    low = 1 + layout.rows_below
    grid[low : low + layout.field_rows, 1:-1] = cells
    pixels: BoolGrid = np.kron(grid, np.ones((layout.scale, layout.scale), dtype=bool))
    return wall_pixels(layout) | pixels


def field_boxes(cells: BoolGrid, layout: BarnLayout) -> tuple[Box, ...]:
    """Boxes covering exactly the occupied cells: each row's runs of occupied cells, a run
    merged with the same run in the rows above it. Few bodies for the sim, the same shape."""
    rows, cols = cells.shape
    open_runs: dict[tuple[int, int], int] = {}  # (first col, last col) -> first row
    spans: list[tuple[int, int, int, int]] = []  # first row, last row, first col, last col
    for r in range(rows + 1):
        runs: set[tuple[int, int]] = set()
        c = 0
        while r < rows and c < cols:
            if cells[r, c]:
                start = c
                while c < cols and cells[r, c]:
                    c += 1
                runs.add((start, c - 1))
            c += 1
        for run in sorted(set(open_runs) - runs):
            spans.append((open_runs.pop(run), r - 1, *run))
        for run in sorted(runs - set(open_runs)):
            open_runs[run] = r
    x0, y0 = layout.cell_m, layout.field_y[0]
    step = layout.cell_m
    return tuple(
        Box(
            x=round(x0 + (c0 + c1 + 1) * step / 2.0, 4),
            y=round(y0 + (r0 + r1 + 1) * step / 2.0, 4),
            size_x=round((c1 - c0 + 1) * step, 4),
            size_y=round((r1 - r0 + 1) * step, 4),
        )
        for r0, r1, c0, c1 in sorted(spans)
    )


def generate_barn_world(
    level: str,
    seed: int,
    robot: RobotFit,
    *,
    name: str | None = None,
    layout: BarnLayout = DEFAULT_LAYOUT,
    max_attempts: int = 5000,
) -> BarnWorld:
    """The BARN-protocol world of ``level`` drawn with ``seed`` for ``robot``: the first
    field of that random stream through which the robot's disc (plus the margin) finds a
    path. The same (level, seed, robot footprint) always gives the same world."""
    rule = level_rule(level)
    rng = world_stream(seed, f"{PROTOCOL}/{level}", UsageError)
    inflation = robot.footprint_radius_m + layout.margin_m
    found = first_passable(
        rng,
        rule,
        layout,
        lambda cells: field_pixels(cells, layout),
        inflation,
        max_attempts,
        lambda occupied, ref: fits(robot, occupied, layout, ref.points),
    )
    if found is not None:
        return BarnWorld(
            name=name or f"barn_{level}_s{seed}",
            level=level,
            seed=seed,
            attempts=found.attempt,
            rule=rule,
            layout=layout,
            robot=robot,
            walls=wall_pixels(layout),
            occupied=found.occupied,
            boxes=field_boxes(found.cells, layout),
            fill_ratio=found.fill_ratio,
            reference=found.reference,
            difficulty=found.difficulty,
        )
    raise UsageError(
        f"no {level} world passable for {robot.name} "
        f"(footprint {robot.footprint_radius_m} m) in {max_attempts} fields (seed {seed})"
    )


def fits(robot: RobotFit, occupied: BoolGrid, layout: BarnLayout, points: Sequence[Point]) -> bool:
    """Whether a robot with a footprint polygon keeps POLYGON_MARGIN_M from every obstacle
    along the reference path, heading along each leg (a disc: the inflated search said so
    already). Turns are not checked in place: the reference path's bends hug the inflated
    obstacles, and a robot drives through them."""
    footprint = robot.footprint
    if footprint.is_disc:
        return True
    res = layout.resolution_m
    return not any(
        collides_on_grid(footprint, pose, occupied, res, ORIGIN, POLYGON_MARGIN_M)
        for pose in path_poses(points, res, math.inf)
    )


def generate_barn_suite(
    levels: Sequence[str], count: int, base_seed: int, robot: RobotFit
) -> list[BarnWorld]:
    """``count`` worlds per level, named ``barn_<level>_<index>`` as the default suite's."""

    def draw(level: str, seed: int, name: str) -> BarnWorld:
        return generate_barn_world(level, seed, robot, name=name)

    return draw_suite(levels, count, base_seed, draw, level_rule, UsageError, "barn")

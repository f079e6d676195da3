"""The planner's footprint check (services/planner/fit.py): a Jackal's box is planned through
a gap it fits straight on, refused where it would cross it at an angle or turn in it, and
planned around it. (The check itself, common.footprint.collides_on_grid, agrees with the
sim's contact test pose by pose: tests/unit/sim/test_footprint_gap.py.)"""

from __future__ import annotations

import itertools
import math

import numpy as np

from common.footprint import Footprint
from common.robotmodel import load_model
from services.planner.fit import collision, fitted
from services.planner.path import plan_path
from services.planner.world_model import MapData, inflation_m

RES = 0.05
BOX = load_model("jackal").footprint


def wall_map(gaps: list[tuple[float, float]], thickness: float = 0.2) -> MapData:
    """A 5 x 6 m room with a wall from x 2.0 across it, open at each (y0, y1) of gaps."""
    occupied = np.zeros((round(6 / RES), round(5 / RES)), dtype=bool)
    occupied[:, round(2.0 / RES) : round((2.0 + thickness) / RES)] = True
    for y0, y1 in gaps:
        occupied[round(y0 / RES) : round(y1 / RES), :] = False
    occupied[[0, -1], :] = True  # the room's walls
    occupied[:, [0, -1]] = True
    return MapData("m", "1", occupied, RES, (0.0, 0.0, 0.0))


def test_straight_through_a_gap_fits_and_across_it_at_an_angle_does_not() -> None:
    data = wall_map([(2.7, 3.3)])  # 0.60 m: the box is 0.43 wide, 0.66 across at 42 degrees
    grid = data.grid(BOX.inscribed_m)
    assert collision(BOX, [(1.0, 3.0), (3.4, 3.0)], data, grid) is None
    hit = collision(BOX, [(1.0, 1.8), (3.4, 4.0)], data, grid)
    assert hit is not None and 1.5 < hit[0] < 2.7  # a corner at the wall
    # turning in place in the gap: the box's corners sweep into the wall, a disc's do not
    turn = [(1.0, 3.0), (2.1, 3.0), (2.1 + 1.0, 3.0 + 0.5)]
    hit = collision(BOX, turn, data, grid)
    assert hit is not None and hit[:2] == (2.1, 3.0) and 0.0 < hit[2] <= math.atan2(0.5, 1.0)
    disc = Footprint.of(0.22)
    assert collision(disc, turn[:2], data, data.grid(0.22)) is None


def test_a_path_the_box_cannot_take_is_planned_around() -> None:
    # the narrow gap is on the straight way, a wide one (1.2 m) farther up
    data = wall_map([(2.7, 3.3), (4.6, 5.8)])
    grid = data.grid(BOX.inscribed_m)
    start, goal = (1.0, 1.2), (3.6, 4.0)
    first = plan_path(grid, start, goal)
    assert first is not None and collision(BOX, first, data, grid) is not None
    wide = data.grid(BOX.circumscribed_m)
    path, how = fitted(BOX, first, data, grid, lambda: wide, plan_path)
    assert how in ("refitted", "circumscribed")
    assert collision(BOX, path, data, grid) is None
    crossing = [
        a[1] + (b[1] - a[1]) * (2.1 - a[0]) / (b[0] - a[0])
        for a, b in itertools.pairwise(path)
        if min(a[0], b[0]) <= 2.1 <= max(a[0], b[0]) and a[0] != b[0]
    ]
    assert crossing and all(4.6 < y < 5.8 for y in crossing)  # through the wide gap


def test_inflation_is_the_inscribed_radius_plus_the_margin() -> None:
    assert BOX.inscribed_m == 0.215
    assert inflation_m(BOX.inscribed_m) == round(0.215 + 0.05, 3)
    assert math.isclose(BOX.circumscribed_m, math.hypot(0.254, 0.215))

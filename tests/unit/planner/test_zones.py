"""Keepout zones on the planner's grid, tick by tick on the in-memory contract with the store
and engine the service runs: a route never crosses one, a goal inside one fails naming it,
and a zone added while the robot follows a route through it makes the robot plan again."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from common.contract import keys
from common.contract.zones import KEEPOUT, SPEED_LIMIT, Zone
from services.planner.keepout import with_keepouts, zone_cells
from tests.unit.planner.harness import ROBOT, Planner

RES = 0.05
ORIGIN = (-1.0, -1.0)
# a wall across the middle of the room, x 1.0-1.5, from y -1.0 up to 1.0: the way round is
# above it, through y 1.0-2.0, or round its bottom end... which is closed (the wall meets
# the room's south wall)
BAND = {"xs": [0.8, 1.7, 1.7, 0.8], "ys": [-2.0, -2.0, 3.0, 3.0]}  # cuts the room in two


def room() -> np.ndarray:
    """4 x 3 m from (-1, -1), walls all round, nothing inside."""
    occupied = np.zeros((60, 80), dtype=bool)
    occupied[0, :] = occupied[-1, :] = occupied[:, 0] = occupied[:, -1] = True
    return occupied


def zone_row(name: str, xs: list[float], ys: list[float], **extra: Any) -> dict[str, Any]:
    row = {"name": name, "kind": KEEPOUT, "xs": xs, "ys": ys, "max_speed_mps": None}
    return row | {"robot_id": None, "description": ""} | extra


def inside(points: np.ndarray, xs: list[float], ys: list[float]) -> bool:
    """Whether any of the route's points, or its segments sampled every 1 cm, is inside."""
    zone = Zone("z", KEEPOUT, tuple(xs), tuple(ys))
    for (ax, ay), (bx, by) in itertools.pairwise(points):
        steps = max(1, int(np.hypot(bx - ax, by - ay) / 0.01))
        for t in np.linspace(0.0, 1.0, steps + 1):
            if zone.contains(ax + (bx - ax) * t, ay + (by - ay) * t):
                return True
    return False


async def started(goal: tuple[float, float]) -> tuple[Planner, int]:
    p = Planner()
    p.map(room(), RES, ORIGIN)
    p.strategy("GOTO_AVOID")
    await p.tick()
    goal_id = p.goal(*goal)
    await p.tick()
    return p, goal_id


def route(p: Planner) -> np.ndarray:
    state = p.store.world.robots[ROBOT]
    assert state.route is not None and state.route.planned
    return state.route.points


async def test_a_route_goes_round_a_keepout_zone_on_its_way() -> None:
    # a block in the straight way from (0, 0) to (2.5, 0)
    xs, ys = [0.8, 1.6, 1.6, 0.8], [-0.5, -0.5, 0.6, 0.6]
    p = Planner()
    p.map(room(), RES, ORIGIN)
    p.contract.insert(keys.ZONE, zone_row("pallets", xs, ys))
    p.strategy("GOTO_AVOID")
    await p.tick()
    goal_id = p.goal(2.5, 0.0)
    await p.tick()
    points = route(p)
    assert not inside(points, xs, ys)
    assert p.goal_row(goal_id)["status"] == "active"
    # the footprint stays out too: every point keeps the inflation (0.155 m) from the zone
    wider = Zone("w", KEEPOUT, (0.65, 1.75, 1.75, 0.65), (-0.65, -0.65, 0.75, 0.75))
    assert not inside(points, list(wider.xs), list(wider.ys))


async def test_a_speed_zone_does_not_change_the_route() -> None:
    p, _ = await started((2.5, 0.0))
    before = route(p).copy()
    row = zone_row("slow", BAND["xs"], BAND["ys"], kind=SPEED_LIMIT, max_speed_mps=0.1)
    p.contract.insert(keys.ZONE, row)
    await p.tick()
    await p.tick()
    assert np.array_equal(route(p), before)


async def test_a_goal_inside_a_keepout_zone_fails_naming_the_zone() -> None:
    p = Planner()
    p.map(room(), RES, ORIGIN)
    p.contract.insert(keys.ZONE, zone_row("dock-7", [2.0, 2.8, 2.8, 2.0], [0.5, 0.5, 1.5, 1.5]))
    p.strategy("GOTO_AVOID")
    await p.tick()
    goal_id = p.goal(2.4, 1.0)
    await p.tick()
    row = p.goal_row(goal_id)
    assert row["status"] == "failed"
    assert row["reason"] == "goal (2.40, 1.00) is inside keepout zone 'dock-7'"


async def test_a_zone_that_cuts_the_room_in_two_fails_the_goal_beyond_it_naming_it() -> None:
    p = Planner()
    p.map(room(), RES, ORIGIN)
    p.contract.insert(keys.ZONE, zone_row("aisle-3", BAND["xs"], BAND["ys"]))
    p.strategy("GOTO_AVOID")
    await p.tick()
    goal_id = p.goal(2.5, 0.0)
    await p.tick()
    row = p.goal_row(goal_id)
    assert row["status"] == "failed"
    assert row["reason"] == (
        "no path on the map from (0.00, 0.00) to the goal outside keepout zone 'aisle-3'"
    )


async def test_a_keepout_zone_added_across_the_route_makes_the_robot_plan_round_it() -> None:
    p, goal_id = await started((2.5, 0.0))
    xs, ys = [0.8, 1.6, 1.6, 0.8], [-0.5, -0.5, 0.6, 0.6]
    assert inside(route(p), xs, ys)  # the straight way, before the zone
    p.contract.insert(keys.ZONE, zone_row("spill", xs, ys))  # notified: the store hears it
    # the activation it wakes reads the zones (the meta rule), the next one plans again
    await p.tick()
    await p.tick()
    assert not inside(route(p), xs, ys)
    assert p.goal_row(goal_id)["status"] == "active"
    # and removed: the straight way again
    p.contract[keys.ZONE].remove(lambda r: r["name"] == "spill")
    p.contract.changed(keys.ZONE, None, None)
    await p.tick()
    await p.tick()
    assert inside(route(p), xs, ys)


async def test_a_zone_for_another_robot_is_not_planned_round() -> None:
    p, _ = await started((2.5, 0.0))
    xs, ys = [0.8, 1.6, 1.6, 0.8], [-0.5, -0.5, 0.6, 0.6]
    p.contract.insert(keys.ZONE, zone_row("theirs", xs, ys, robot_id="r2"))
    await p.tick()
    assert inside(route(p), xs, ys)


def test_a_zone_covers_the_cells_whose_centres_are_inside_it_and_those_its_edges_cross() -> None:
    zone = Zone("z", KEEPOUT, (0.15, 0.35, 0.35, 0.15), (0.15, 0.15, 0.35, 0.35))
    cells = zone_cells(zone, (6, 6), 0.1, (0.0, 0.0, 0.0))
    expected = np.zeros((6, 6), dtype=bool)
    expected[1:4, 1:4] = True  # cell 2's centre is inside; cells 1 and 3 hold the edges
    assert np.array_equal(cells, expected)
    # narrower than a cell, still closes the way
    thin = Zone("t", KEEPOUT, (0.05, 0.55, 0.55, 0.05), (0.22, 0.22, 0.24, 0.24))
    assert zone_cells(thin, (6, 6), 0.1, (0.0, 0.0, 0.0))[2, :6].all()
    # off the map: nothing; the map's own obstacles stay
    far = Zone("f", KEEPOUT, (5.0, 6.0, 6.0), (5.0, 5.0, 6.0))
    occupied = np.eye(6, dtype=bool)
    assert np.array_equal(with_keepouts(occupied, [far], 0.1, (0.0, 0.0, 0.0)), occupied)


def test_the_cells_match_the_zones_own_inside_test_on_random_star_polygons() -> None:
    rng = np.random.default_rng(7)
    res, origin = 0.1, (-0.3, 0.2, 0.0)
    for _ in range(30):
        n = int(rng.integers(3, 40))
        angles = np.sort(rng.uniform(0, 2 * np.pi, n))
        radii = rng.uniform(0.3, 2.0, n)
        cx, cy = rng.uniform(0.5, 3.5, 2)
        xs = tuple(float(v) for v in cx + radii * np.cos(angles))
        ys = tuple(float(v) for v in cy + radii * np.sin(angles))
        zone = Zone("star", KEEPOUT, xs, ys)
        cells = zone_cells(zone, (40, 40), res, origin)
        for row in range(40):
            for col in range(40):
                x, y = origin[0] + (col + 0.5) * res, origin[1] + (row + 0.5) * res
                if zone.contains(x, y):
                    assert cells[row, col], (zone, row, col)


def test_a_zone_far_larger_than_the_map_covers_all_of_it() -> None:
    huge = Zone("all", KEEPOUT, (-1.0e5, 1.0e5, 1.0e5, -1.0e5), (-1.0e5, -1.0e5, 1.0e5, 1.0e5))
    assert zone_cells(huge, (60, 80), 0.05, (-1.0, -1.0, 0.0)).all()
    # one whose edge crosses the map from far away marks the cells it crosses, no others
    sliver = Zone("s", KEEPOUT, (-1.0e5, 1.0e5, 1.0e5), (0.01, 0.01, 0.04))
    cells = zone_cells(sliver, (60, 80), 0.05, (-1.0, -1.0, 0.0))
    assert cells[20].all() and cells.sum() == 80

"""The grid path planner on hand-made grids: walls, inflation, clearance costs, no way through."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np

from services.planner.path import (
    OCCUPIED_AT,
    PlanGrid,
    astar,
    clearance_cells,
    coarsen,
    inflate,
    path_length,
    plan_grid,
    plan_path,
    shortcut,
    visible,
    with_obstacles,
)

RES = 0.1


def room(width: int = 30, height: int = 20) -> np.ndarray:
    """A walled room: occupied border, free inside."""
    occupied = np.zeros((height, width), dtype=bool)
    occupied[0, :] = occupied[-1, :] = occupied[:, 0] = occupied[:, -1] = True
    return occupied


def wall_with_gap(gap_rows: range | None) -> np.ndarray:
    """A vertical wall at column 15 across the room, with an optional gap."""
    occupied = room()
    occupied[:, 15] = True
    if gap_rows is not None:
        occupied[gap_rows.start : gap_rows.stop, 15] = False
    return occupied


def test_astar_goes_around_a_wall_through_the_gap() -> None:
    grid = PlanGrid(wall_with_gap(range(15, 19)), RES, 0.0, 0.0)
    cells = astar(grid, (3, 3), (27, 3))
    assert cells is not None
    assert cells[0] == (3, 3) and cells[-1] == (27, 3)
    crossing = [c for c in cells if c[0] == 15]
    assert crossing and all(15 <= r < 19 for _, r in crossing)
    for (c0, r0), (c1, r1) in itertools.pairwise(cells):
        assert max(abs(c1 - c0), abs(r1 - r0)) == 1  # 8-connected steps
        assert not grid.blocked[r1, c1]


def test_astar_returns_none_when_blocked() -> None:
    grid = PlanGrid(wall_with_gap(None), RES, 0.0, 0.0)
    assert astar(grid, (3, 3), (27, 3)) is None
    assert plan_path(grid, (0.35, 0.35), (2.75, 0.35)) is None


def test_astar_refuses_a_blocked_start_or_goal() -> None:
    grid = PlanGrid(wall_with_gap(range(15, 19)), RES, 0.0, 0.0)
    assert astar(grid, (15, 3), (27, 3)) is None
    assert astar(grid, (3, 3), (0, 0)) is None


def test_diagonal_steps_do_not_cut_corners() -> None:
    occupied = np.zeros((3, 3), dtype=bool)
    occupied[0, 1] = occupied[1, 0] = True  # (0,0) can only leave diagonally past two walls
    grid = PlanGrid(occupied, RES, 0.0, 0.0)
    assert astar(grid, (0, 0), (2, 2)) is None


def test_inflation_closes_a_gap_narrower_than_the_robot() -> None:
    # a 0.4 m gap: open for a point, closed for a robot of radius 0.155 (0.31 m plus the walls)
    occupied = wall_with_gap(range(8, 12))
    assert plan_path(plan_grid(occupied, RES, (0.0, 0.0, 0.0), 0.0), (0.5, 0.5), (2.5, 0.5))
    assert (
        plan_path(plan_grid(occupied, RES, (0.0, 0.0, 0.0), 0.25), (0.5, 0.5), (2.5, 0.5)) is None
    )
    # a 0.8 m gap stays open, and the path keeps its clearance from the gap's edges
    wide = wall_with_gap(range(6, 14))
    grid = plan_grid(wide, RES, (0.0, 0.0, 0.0), 0.155)
    points = plan_path(grid, (0.5, 0.5), (2.5, 0.5))
    assert points is not None
    occupied_xy = np.argwhere(wide)[:, ::-1] * RES + RES / 2  # (x, y) centres of occupied cells
    for a, b in itertools.pairwise(points):
        for t in np.linspace(0, 1, 50):
            p = np.array(a) + t * (np.array(b) - np.array(a))
            assert np.min(np.hypot(*(occupied_xy - p).T)) > 0.155 - 1e-9


def test_inflate_is_a_disc() -> None:
    occupied = np.zeros((9, 9), dtype=bool)
    occupied[4, 4] = True
    grown = inflate(occupied, 2.0)
    assert grown[4, 2] and grown[2, 4] and grown[3, 3]
    assert not grown[2, 2]  # sqrt(8) > 2
    assert grown.sum() == 13


def test_shortcut_straightens_a_staircase_in_the_open() -> None:
    grid = PlanGrid(room(), RES, 0.0, 0.0)
    cells = astar(grid, (2, 2), (25, 15))
    assert cells is not None and len(cells) > 10
    assert shortcut(grid, cells) == [(2, 2), (25, 15)]
    assert visible(grid, (2.5, 2.5), (25.5, 15.5))


def test_plan_path_around_a_wall_bends_at_the_gap() -> None:
    grid = plan_grid(wall_with_gap(range(14, 19)), RES, (0.0, 0.0, 0.0), 0.1)
    points = plan_path(grid, (0.35, 0.35), (2.65, 0.35))
    assert points is not None
    assert points[0] == (0.35, 0.35) and points[-1] == (2.65, 0.35)
    assert 3 <= len(points) <= 6
    assert path_length(points) > 3.0  # 2.3 m straight, but it had to climb to the gap
    assert any(p[1] > 1.3 for p in points)


def test_world_and_cell_coordinates_round_trip() -> None:
    grid = PlanGrid(room(), 0.05, -0.2, -0.2)
    assert grid.cell_of(-0.2, -0.2) == (0, 0)
    assert grid.cell_of(0.0, 0.0) == (4, 4)
    assert grid.to_world((4, 4)) == (-0.2 + 0.225, -0.2 + 0.225)


def test_coarsen_keeps_every_obstacle() -> None:
    blocked = np.zeros((5, 7), dtype=bool)
    blocked[4, 6] = True
    pooled = coarsen(blocked, 2)
    assert pooled.shape == (3, 4) and pooled[2, 3]
    # the padding past the edge counts as blocked (a partial cell is not trusted)
    assert pooled[:2, :3].sum() == 0 and pooled[2, :].all() and pooled[:, 3].all()
    grid = plan_grid(np.zeros((400, 400), dtype=bool), 0.05, (0.0, 0.0, 0.0), 0.1, max_cells=40_000)
    assert grid.shape == (200, 200) and grid.resolution == 0.1


# -- clearance: the distance transform, costs, and paths that keep away from walls -----------


def test_clearance_cells_is_the_euclidean_distance_up_to_the_cap() -> None:
    rng = np.random.default_rng(3)
    occupied = rng.random((30, 40)) < 0.03
    occupied[0, 0] = True
    got = clearance_cells(occupied, 6)
    rows, cols = np.nonzero(occupied)
    rr, cc = np.indices(occupied.shape)
    exact = np.min(np.hypot(rr[..., None] - rows, cc[..., None] - cols), axis=-1)
    assert np.allclose(got, np.minimum(exact, 6.0))
    # a cap beyond the grid (a robot row's footprint of any size) is the exact distance,
    # worked out in one pass per column of the grid, not per cell of the cap
    assert np.allclose(clearance_cells(occupied, 10**9), exact)
    assert clearance_cells(np.zeros((3, 4), dtype=bool), 10**9).min() == 10**9


def aisle_map() -> np.ndarray:
    """6 x 4 m at 5 cm: walls all round and a block (a rack) in the middle, leaving 1.0 m
    aisles above and below it, and 1.0 m at either end."""
    occupied = np.zeros((80, 120), dtype=bool)
    occupied[0, :] = occupied[-1, :] = occupied[:, 0] = occupied[:, -1] = True
    occupied[20:60, 20:100] = True  # the rack: x 1.0-5.0, y 1.0-3.0
    return occupied


def clearance_along(points: list[tuple[float, float]], occupied: np.ndarray) -> float:
    """The smallest distance from the path (sampled every cm) to an occupied cell's centre."""
    rows, cols = np.nonzero(occupied)
    xy = np.column_stack(((cols + 0.5) * 0.05, (rows + 0.5) * 0.05))
    worst = np.inf
    for a, b in itertools.pairwise(points):
        n = max(2, int(math.hypot(b[0] - a[0], b[1] - a[1]) / 0.01))
        for t in np.linspace(0, 1, n):
            p = np.array(a) + t * (np.array(b) - np.array(a))
            worst = min(worst, float(np.min(np.hypot(*(xy - p).T))))
    return worst


def test_the_path_runs_along_the_middle_of_an_aisle_and_wide_round_corners() -> None:
    occupied = aisle_map()
    grid = plan_grid(occupied, 0.05, (0.0, 0.0, 0.0), 0.155)
    # From near the wall at the lower aisle's west end, round the rack's corner, to the
    # upper aisle's east end.
    points = plan_path(grid, (0.5, 0.25), (5.5, 3.5))
    assert points is not None
    # The aisles are 0.95 m wide (0.475 m from the middle to the walls' cell centres): once
    # off the wall, the path keeps near the middle all along, corners included...
    assert math.hypot(points[1][0] - 0.5, points[1][1] - 0.25) < 1.0
    assert clearance_along(points[1:], occupied) > 0.38
    # ...where the bare shortest path (no clearance costs) grazes the inflation.
    bare = plan_grid(occupied, 0.05, (0.0, 0.0, 0.0), 0.155, cost_weight=0.0)
    bare_points = plan_path(bare, (0.5, 0.25), (5.5, 3.5))
    assert bare_points is not None and clearance_along(bare_points, occupied) < 0.2
    # Along the lower aisle (y 0.05-1.0) it keeps to the middle line.
    assert all(abs(p[1] - 0.525) < 0.06 for p in points[1:-1] if p[0] < 5.0)
    assert path_length(points) < 1.15 * path_length(bare_points)


def test_the_shortcut_does_not_cut_back_to_the_walls() -> None:
    occupied = aisle_map()
    grid = plan_grid(occupied, 0.05, (0.0, 0.0, 0.0), 0.155)
    cells = astar(grid, grid.cell_of(0.5, 0.5), grid.cell_of(5.5, 3.5))
    assert cells is not None
    kept = shortcut(grid, cells)
    assert len(kept) < len(cells) // 5  # still a few straight segments
    worst = min(grid.clearance_at(c) for c in cells)
    centres = [(c + 0.5, r + 0.5) for c, r in kept]
    for a, b in itertools.pairwise(centres):
        assert visible(grid, a, b, clearance_m=worst)


def test_visible_checks_the_clearance_when_asked() -> None:
    grid = plan_grid(aisle_map(), 0.05, (0.0, 0.0, 0.0), 0.155)
    # along the lower aisle, 0.25 m from the rack: in sight, but not with 0.4 m of clearance
    a, b = grid.to_cell(1.5, 0.75), grid.to_cell(4.5, 0.75)
    assert visible(grid, a, b)
    assert not visible(grid, a, b, clearance_m=0.4)
    assert visible(grid, grid.to_cell(1.5, 0.5), grid.to_cell(4.5, 0.5), clearance_m=0.4)


def test_extra_obstacles_are_blocked_and_costed_like_the_map() -> None:
    occupied = room(60, 40)
    grid = plan_grid(occupied, 0.05, (0.0, 0.0, 0.0), 0.155)
    straight = plan_path(grid, (0.5, 1.0), (2.5, 1.0))
    assert straight == [(0.5, 1.0), (2.5, 1.0)]
    # a crate on the straight line, seen by the lidar: the path goes round it, with room
    crate = np.array(
        [(x, y) for x in np.arange(1.4, 1.65, 0.05) for y in np.arange(0.8, 1.25, 0.05)]
    )
    around = plan_path(with_obstacles(grid, crate), (0.5, 1.0), (2.5, 1.0))
    assert around is not None and len(around) > 2
    gaps = [
        min(float(np.min(np.hypot(*(crate - p).T))) for p in sampled)
        for sampled in [
            [np.array(a) + t * (np.array(b) - np.array(a)) for t in np.linspace(0, 1, 40)]
            for a, b in itertools.pairwise(around)
        ]
    ]
    assert min(gaps) > 0.3
    assert grid.blocked.sum() < with_obstacles(grid, crate).blocked.sum()
    assert plan_path(grid, (0.5, 1.0), (2.5, 1.0)) == straight  # the map's grid is unchanged
    # a wall of them across the room: no way through
    wall = np.array([(1.5, y) for y in np.arange(0.0, 2.0, 0.05)])
    assert plan_path(with_obstacles(grid, wall), (0.5, 1.0), (2.5, 1.0)) is None


def test_planning_on_the_shipped_warehouse_map_keeps_clear() -> None:
    # How fast it plans is a benchmark's figure (the planner's rule times in `pnav bench
    # latency` and `pnav bench nav`), not this test's: a wall-clock bound here failed on a
    # loaded machine with nothing wrong.
    from services.sim.mapserver import load_map  # the map files the sim serves

    shipped = load_map(Path(__file__).resolve().parents[3] / "worlds/maps/warehouse.yaml")
    occupied = shipped.cells >= OCCUPIED_AT
    grid = plan_grid(occupied, shipped.resolution, shipped.origin, 0.155)
    points = plan_path(grid, (1.0, 2.5), (8.8, 6.6))
    assert points is not None
    rows, cols = np.nonzero(occupied)
    ox, oy, _ = shipped.origin
    walls = np.column_stack((ox + (cols + 0.5) * 0.05, oy + (rows + 0.5) * 0.05))
    for a, b in itertools.pairwise(points):
        for t in np.linspace(0, 1, 30):
            p = np.array(a) + t * (np.array(b) - np.array(a))
            assert np.min(np.hypot(*(walls - p).T)) > 0.4  # the aisles are 1.0 and 1.2 m
    # into an aisle between two racks (x 3.0-4.2): down its middle
    points = plan_path(grid, (1.0, 2.5), (3.7, 2.5))
    assert points is not None
    assert all(abs(p[0] - 3.6) < 0.1 for p in points[1:-1] if p[1] < 3.6)

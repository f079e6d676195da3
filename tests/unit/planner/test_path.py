"""The grid path planner on hand-made grids: walls, inflation, no way through."""

from __future__ import annotations

import itertools

import numpy as np

from services.planner.path import (
    PlanGrid,
    astar,
    coarsen,
    inflate,
    path_length,
    plan_grid,
    plan_path,
    shortcut,
    visible,
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

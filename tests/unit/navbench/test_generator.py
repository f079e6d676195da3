"""The generator's guarantees: a path for the robot's footprint always exists, the start and
goal are free, a seed always gives the same world, and the levels differ."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from pnav.bench.nav.automaton import AutomatonRule, neighbour_counts, smooth
from pnav.bench.nav.generator import (
    DEFAULT_LAYOUT,
    LEVELS,
    ORIGIN,
    GeneratedWorld,
    Layout,
    generate_suite,
    generate_world,
    rasterize,
)
from pnav.bench.nav.search import astar, inflate, reference_path
from pnav.bench.nav.worldfile import write_world
from services.sim.robot import BURGER
from tests.unit.navbench.conftest import min_clearance

pytestmark = pytest.mark.timeout(60)

SEEDS = range(10)


@pytest.fixture(scope="module")
def worlds() -> dict[str, list[GeneratedWorld]]:
    return {level: [generate_world(level, seed) for seed in SEEDS] for level in LEVELS}


def test_the_levels_are_easy_medium_hard() -> None:
    assert list(LEVELS) == ["easy", "medium", "hard"]


def test_every_world_has_a_path_the_robot_fits_through(
    worlds: dict[str, list[GeneratedWorld]],
) -> None:
    for level, group in worlds.items():
        for w in group:
            ref = w.reference
            assert ref.points[0] == w.start[:2] and ref.points[-1] == w.goal, w.name
            # checked apart from the generator: the disc never touches an occupied cell
            clear = min_clearance(w.occupied, w.layout.resolution_m, ref.points)
            assert clear >= BURGER.footprint_radius_m, (level, w.seed, clear)
            assert ref.length_m <= ref.grid_length_m + 1e-9
            assert ref.length_m >= np.hypot(*np.subtract(w.goal, w.start[:2])) - 1e-9


def test_the_clearance_check_can_fail(worlds: dict[str, list[GeneratedWorld]]) -> None:
    # the straight line through a hard field runs into something in most worlds
    hits = [
        min_clearance(w.occupied, w.layout.resolution_m, [w.start[:2], w.goal])
        < BURGER.footprint_radius_m
        for w in worlds["hard"]
    ]
    assert sum(hits) >= len(hits) // 2


def test_start_and_goal_are_free_and_in_the_zones(
    worlds: dict[str, list[GeneratedWorld]],
) -> None:
    layout = DEFAULT_LAYOUT
    low, high = layout.field_y
    for group in worlds.values():
        for w in group:
            for x, y in (w.start[:2], w.goal):
                assert min_clearance(w.occupied, layout.resolution_m, [(x, y), (x, y)]) >= 0.3
            assert w.start[1] < low and w.goal[1] > high
    # the walls close the map, and the field spans the whole width between them
    w = worlds["hard"][0]
    assert w.occupied[0].all() and w.occupied[-1].all()
    assert w.occupied[:, 0].all() and w.occupied[:, -1].all()


def test_a_map_without_a_way_through_is_refused() -> None:
    layout = DEFAULT_LAYOUT
    cells = np.zeros((layout.field_rows, layout.field_cols), dtype=bool)
    cells[10, :] = True  # one solid row across the field
    occupied = rasterize(cells, layout)
    x, y, _ = layout.start
    args = (layout.resolution_m, ORIGIN, (x, y), layout.goal, layout.inflation_m)
    assert reference_path(occupied, *args) is None
    # a gap of two cells (0.30 m) is narrower than the disc plus margin (0.31 m)...
    cells[10, 14:16] = False
    assert reference_path(rasterize(cells, layout), *args) is None
    # ...three (0.45 m) let it through, and the path goes through the gap
    cells[10, 13:16] = False
    occupied = rasterize(cells, layout)
    ref = reference_path(occupied, *args)
    assert ref is not None
    gap_y = (1 + layout.zone_rows + 10.5) * layout.cell_m
    pts = np.array(ref.points)
    x_at_gap = np.interp(gap_y, pts[:, 1], pts[:, 0])  # the path climbs monotonically here
    # the gap spans map x 2.10..2.55 m (field columns 13..15, after the 0.15 m wall)
    assert 2.10 + BURGER.footprint_radius_m <= x_at_gap <= 2.55 - BURGER.footprint_radius_m
    assert min_clearance(occupied, layout.resolution_m, ref.points) >= BURGER.footprint_radius_m


def test_rejected_fields_are_drawn_again(worlds: dict[str, list[GeneratedWorld]]) -> None:
    # the hard level refuses many fields: the worlds kept still all have a path (above)
    assert any(w.attempts > 1 for w in worlds["hard"])
    assert all(w.attempts >= 1 for group in worlds.values() for w in group)


def test_same_seed_same_bytes(tmp_path: Path) -> None:
    for level in LEVELS:
        a = generate_world(level, 42)
        b = generate_world(level, 42)
        write_world(a, tmp_path / "a", header="test")
        write_world(b, tmp_path / "b", header="test")
    files = sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*.*"))
    assert len(files) == 9  # 3 levels x world, map YAML, PGM
    for rel in files:
        assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes(), rel
    # and another seed, or the same seed at another level, is another world
    base = generate_world("medium", 42).occupied
    assert not np.array_equal(base, generate_world("medium", 43).occupied)
    assert not np.array_equal(base, generate_world("hard", 42).occupied)


def test_suite_names_and_seeds() -> None:
    suite = generate_suite(["easy", "hard"], 2, 3)
    assert [(w.name, w.seed) for w in suite] == [
        ("barn_easy_000", 3000),
        ("barn_easy_001", 3001),
        ("barn_hard_000", 3000),
        ("barn_hard_001", 3001),
    ]
    assert np.array_equal(suite[3].occupied, generate_world("hard", 3001).occupied)
    with pytest.raises(ValueError, match="unknown level"):
        generate_suite(["easy", "insane"], 1, 0)


def mean(values: list[float]) -> float:
    return float(np.mean(values))


def test_the_levels_differ(worlds: dict[str, list[GeneratedWorld]]) -> None:
    easy, medium, hard = worlds["easy"], worlds["medium"], worlds["hard"]
    fill = [mean([w.fill_ratio for w in g]) for g in (easy, medium, hard)]
    assert fill[0] < fill[1] < fill[2]
    for metric, harder_is in (
        ("closest_obstacle_m", "lower"),
        ("avg_visibility_m", "lower"),
        ("characteristic_dimension_m", "lower"),
        ("dispersion", "higher"),
        ("tortuosity", "higher"),
    ):
        means = [mean([getattr(w.difficulty, metric) for w in g]) for g in (easy, medium, hard)]
        if harder_is == "lower":
            assert means[0] > means[1] > means[2], (metric, means)
        else:
            assert means[0] < means[1] < means[2], (metric, means)
    lengths = [mean([w.reference.length_m for w in g]) for g in (easy, medium, hard)]
    assert lengths[0] < lengths[2]


def test_difficulty_metrics_are_sane(worlds: dict[str, list[GeneratedWorld]]) -> None:
    for group in worlds.values():
        for w in group:
            d = w.difficulty
            # the path keeps the disc plus margin off the cells, less half a pixel diagonal
            assert d.closest_obstacle_m >= BURGER.footprint_radius_m
            assert 0.0 < d.avg_visibility_m <= 3.5
            assert d.characteristic_dimension_m <= 2 * 3.5
            assert d.dispersion >= 0.0
            assert d.tortuosity == pytest.approx(w.reference.length_m / 5.4)


def test_automaton_rule_by_hand() -> None:
    rule = AutomatonRule(fill_probability=0.3, smoothing_iterations=1)
    field = np.zeros((5, 5), dtype=bool)
    field[2, 2] = True  # a lone cell: no occupied neighbour, clears
    field[0, 0:3] = True  # cell (1, 1) sees 3 of them: unchanged (free)
    field[1, 0] = field[2, 0] = True  # now (1, 1) sees 5: fills
    counts = neighbour_counts(field, sides_occupied=False)
    assert counts[1, 1] == 6  # (0,0) (0,1) (0,2) (1,0) (2,0) and the lone (2,2)
    after = smooth(field, rule)
    assert not after[2, 2]
    assert after[1, 1]
    # the side walls count (they run on past the field, beside the zones): a cell on the
    # left edge has 3 wall neighbours, one inside none; the zones above and below are free
    empty = np.zeros((4, 4), dtype=bool)
    counts = neighbour_counts(empty)
    assert counts[1, 0] == 3 and counts[0, 0] == 3 and counts[3, 3] == 3
    assert counts[1, 1] == 0 and counts[0, 1] == 0 and counts[3, 2] == 0
    with pytest.raises(ValueError):
        AutomatonRule(fill_probability=1.5, smoothing_iterations=1)
    with pytest.raises(ValueError):
        AutomatonRule(fill_probability=0.3, smoothing_iterations=1, fill_threshold=1)


def test_inflation_and_astar_on_a_tiny_grid() -> None:
    occupied = np.zeros((7, 7), dtype=bool)
    occupied[3, 3] = True
    # radius 0.6 cells: the 4 side neighbours are 0.5 cells from the square, corners 0.71
    blocked = inflate(occupied, 1.0, 0.6)
    assert blocked[3, 3] and blocked[3, 2] and blocked[2, 3] and blocked[4, 3]
    assert not blocked[2, 2] and not blocked[3, 1] and not blocked[4, 4]
    # beyond the map's edge counts as occupied: row 0's centres are 0.5 cells from it
    assert blocked[0].all() and blocked[:, 6].all() and not blocked[1, 1]
    free = ~blocked
    path = astar(free, (1, 1), (5, 5))
    assert path is not None and path[0] == (1, 1) and path[-1] == (5, 5)
    # round the blocked plus sign: along two sides, one diagonal step to cut the corner
    steps = list(itertools.pairwise(path))
    cost = sum(np.hypot(r1 - r0, c1 - c0) for (r0, c0), (r1, c1) in steps)
    assert cost == pytest.approx(6 + np.sqrt(2))
    # no diagonal step may clip a blocked cell's corner
    for (r0, c0), (r1, c1) in itertools.pairwise(path):
        assert free[r0, c1] and free[r1, c0]
    walled = free.copy()
    walled[:, 2] = False
    assert astar(walled, (1, 1), (5, 5)) is None


def test_layout_checks() -> None:
    with pytest.raises(ValueError):
        Layout(cell_m=0.12)  # not a whole number of 0.05 m pixels
    with pytest.raises(ValueError):
        Layout(margin_m=0.02)  # below half a pixel diagonal: the guarantee would not hold
    assert DEFAULT_LAYOUT.scale == 3
    assert (DEFAULT_LAYOUT.width_m, DEFAULT_LAYOUT.height_m) == pytest.approx((4.8, 6.6))

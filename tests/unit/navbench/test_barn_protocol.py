"""The BARN protocol's worlds (``pnav worlds generate --protocol barn``): the same level, seed
and robot give the same bytes; BARN's layout (start 2 m below the field, goal 10 m straight
ahead); the obstacles exist only in the sim world, not in the map; the robot's disc fits
along the stored path, checked against the world as the sim loads it."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pytest

from common.errors import UsageError
from pnav.bench.nav import barn, worlds_cli
from pnav.bench.nav.barn import BarnLayout, field_boxes, generate_barn_world, time_limit
from pnav.bench.nav.barnfile import write_barn_world
from pnav.bench.nav.robots import RobotFit, resolve_model
from pnav.bench.nav.worldfile import occupied_cells, read_benchmark
from pnav.cli import program as cli
from services.sim.world_spec import load_world
from tests.unit.navbench.conftest import min_clearance

pytestmark = pytest.mark.timeout(120)

# the shipped models, as the sim loads them from the world files written here
JACKAL = resolve_model("jackal")  # 2 m/s, the circle inscribed in its 0.508 x 0.430 m body
BURGER = resolve_model("turtlebot3_burger")
LAYOUT = BarnLayout()


def world_truth(path: Path) -> tuple[np.ndarray, float]:
    """The occupied map pixels of a world file as the sim loads it: its map's cells plus its
    obstacles drawn in (a pixel whose centre lies inside a box), and the resolution."""
    world = load_world(path)
    grid = world.grid
    occupied = occupied_cells(grid).copy()
    res = grid.resolution
    ys, xs = np.mgrid[0 : occupied.shape[0], 0 : occupied.shape[1]]
    cx, cy = (xs + 0.5) * res + grid.origin[0], (ys + 0.5) * res + grid.origin[1]
    for ob in world.obstacles:
        assert ob.shape == "box" and ob.yaw == 0.0
        inside = (np.abs(cx - ob.x) < ob.size[0] / 2) & (np.abs(cy - ob.y) < ob.size[1] / 2)
        occupied |= inside
    return occupied, res


def test_same_level_seed_and_robot_give_the_same_bytes(tmp_path: Path) -> None:
    for folder in ("a", "b"):
        write_barn_world(generate_barn_world("medium", 7, JACKAL), tmp_path / folder)
    for rel in ("barn_medium_s7.yaml", "maps/barn_medium_s7.yaml", "maps/barn_medium_s7.pgm"):
        assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes()
    other = generate_barn_world("medium", 8, JACKAL)
    assert other.boxes != generate_barn_world("medium", 7, JACKAL).boxes


def test_the_goal_lies_10_m_straight_ahead_and_the_start_2_m_below_the_field(
    tmp_path: Path,
) -> None:
    bench = read_benchmark(write_barn_world(generate_barn_world("easy", 3, JACKAL), tmp_path))
    x, y, yaw = bench.start
    assert yaw == pytest.approx(math.pi / 2, abs=1e-6)  # facing +y, the field
    heading = (math.cos(yaw), math.sin(yaw))
    ahead = (bench.goal[0] - x) * heading[0] + (bench.goal[1] - y) * heading[1]
    assert ahead == pytest.approx(10.0, abs=1e-3)
    assert math.dist((x, y), bench.goal) == pytest.approx(10.0, abs=1e-3)
    field_low, field_high = LAYOUT.field_y
    assert field_low - y == pytest.approx(2.0, abs=1e-9)
    assert y < field_low < field_high < bench.goal[1]
    # every obstacle lies inside the field band, none in the start or goal zones
    for ob in load_world(bench.world_file).obstacles:
        low, high = ob.y - ob.size[1] / 2, ob.y + ob.size[1] / 2
        assert field_low - 1e-9 <= low and high <= field_high + 1e-9
    assert (bench.protocol, bench.model, bench.goal_tolerance_m) == ("barn", "jackal", 1.0)
    assert (bench.top_speed_mps, bench.time_limit_s) == (2.0, 100.0)
    assert bench.optimal_time_s == pytest.approx(bench.reference_length_m / 2.0, abs=1e-3)


def test_the_map_has_only_the_walls_the_obstacles_only_the_sim_world(tmp_path: Path) -> None:
    world = generate_barn_world("hard", 2, JACKAL)
    path = write_barn_world(world, tmp_path)
    loaded = load_world(path)
    mapped = occupied_cells(loaded.grid)
    scale = LAYOUT.scale
    border = np.ones_like(mapped)
    border[scale:-scale, scale:-scale] = False
    assert (mapped == border).all()  # the planner's map: the walls, nothing else
    assert len(loaded.obstacles) == len(world.boxes) > 10
    # drawn in, the obstacles are exactly the field the generator checked the path on
    truth, _ = world_truth(path)
    assert (truth == world.occupied).all()
    assert not (world.occupied & ~world.walls)[: scale * (1 + LAYOUT.rows_below)].any()


def test_the_robots_disc_fits_along_the_stored_path_in_the_world_as_loaded(
    tmp_path: Path,
) -> None:
    for level, seed in (("easy", 0), ("medium", 1), ("hard", 4)):
        bench = read_benchmark(write_barn_world(generate_barn_world(level, seed, JACKAL), tmp_path))
        truth, res = world_truth(bench.world_file)
        clear = min_clearance(truth, res, bench.reference_path)
        assert clear >= JACKAL.footprint_radius_m + 0.015, (level, seed, clear)
        # the path goes through the field: there is no way round it
        assert min(p[1] for p in bench.reference_path) < LAYOUT.field_y[0]
        assert max(p[1] for p in bench.reference_path) > LAYOUT.field_y[1]


def test_a_bigger_robot_gets_a_world_with_room_for_it() -> None:
    small = generate_barn_world("hard", 5, BURGER)
    big = generate_barn_world("hard", 5, JACKAL)
    assert small.attempts <= big.attempts  # same stream: the Burger fits through more fields
    assert min_clearance(big.occupied, 0.05, big.reference.points) >= 0.22 + 0.015
    assert (JACKAL.footprint_radius_m, BURGER.footprint_radius_m) == (0.22, 0.105)
    with pytest.raises(UsageError, match="no hard world passable for huge"):
        generate_barn_world("hard", 5, RobotFit("huge", 1.0, 2.3), max_attempts=3)


def test_boxes_cover_exactly_the_occupied_cells() -> None:
    rng = np.random.default_rng(4)
    cells = rng.random((30, 30)) < 0.4
    boxes = field_boxes(cells, LAYOUT)
    assert len(boxes) < cells.sum()  # runs merged
    covered = np.zeros((30, 30), dtype=int)
    for b in boxes:
        c0 = round((b.x - b.size_x / 2 - LAYOUT.cell_m) / LAYOUT.cell_m)
        r0 = round((b.y - b.size_y / 2 - LAYOUT.field_y[0]) / LAYOUT.cell_m)
        covered[
            r0 : r0 + round(b.size_y / LAYOUT.cell_m), c0 : c0 + round(b.size_x / LAYOUT.cell_m)
        ] += 1
    assert (covered == cells).all()  # every occupied cell once, no free cell


def test_levels_fill_more_and_leave_less_room_from_easy_to_hard() -> None:
    worlds = {lv: [generate_barn_world(lv, s, JACKAL) for s in range(8)] for lv in barn.LEVELS}

    def mean(level: str, value: str) -> float:
        got = [getattr(w.difficulty, value, None) or getattr(w, value) for w in worlds[level]]
        return float(np.mean(got))

    for value in ("fill_ratio", "dispersion"):
        assert mean("easy", value) < mean("medium", value) < mean("hard", value)
    for value in ("closest_obstacle_m", "characteristic_dimension_m", "avg_visibility_m"):
        assert mean("easy", value) > mean("medium", value) > mean("hard", value)


def test_the_time_limit_is_barns_100_s_at_2_mps_scaled_to_the_robot() -> None:
    assert time_limit(2.0) == 100.0
    assert time_limit(1.0) == 200.0
    assert time_limit(0.22) == 910.0  # 909.1 s, rounded up to whole 10 s
    with pytest.raises(UsageError):
        time_limit(0.0)


def test_model_needs_the_barn_protocol_and_levels_are_checked(tmp_path: Path) -> None:
    args = argparse.Namespace(
        out=tmp_path, count=1, seed=0, levels="easy", png=False, protocol="default", model="x"
    )
    with pytest.raises(UsageError, match="--model needs --protocol barn"):
        worlds_cli.generate(args)
    args.protocol, args.levels = "barn", "easy,brutal"
    with pytest.raises(UsageError, match="unknown brutal"):
        worlds_cli.generate(args)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize(
    "argv",
    [
        ["worlds", "generate", "--protocol", "barn", "--model", "nope", "--out", "{out}"],
        ["worlds", "generate", "--model", "jackal", "--out", "{out}"],
        ["bench", "nav", "--suite", "worlds/barn_protocol", "--model", "nope"],
    ],
)
def test_a_bad_model_is_refused_in_one_line_before_anything_runs(
    argv: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "suite"
    code = cli.main([a.replace("{out}", str(out)) for a in argv])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert "model" in err
    assert not out.exists()

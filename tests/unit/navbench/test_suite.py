"""The shipped suite (worlds/barn): it loads in the sim, its stored reference lengths match a
recomputation on the maps as the sim reads them, and the command in SUITE.md rebuilds it."""

from __future__ import annotations

import re
from collections import Counter
from pathlib import Path

import pytest

from pnav.bench.nav.generator import LEVELS, generate_world
from pnav.bench.nav.search import reference_path
from pnav.bench.nav.worldfile import load_suite, occupied_cells, read_benchmark, write_world
from pnav.bench.nav.worlds_cli import world_header
from services.sim.robot import BURGER
from services.sim.world_spec import load_world
from tests.unit.navbench.conftest import min_clearance

pytestmark = pytest.mark.timeout(60)

SUITE = Path(__file__).resolve().parents[3] / "worlds" / "barn"


def test_the_suite_has_20_worlds_per_level() -> None:
    suite = load_suite(SUITE)
    assert len(suite) >= 60
    assert Counter(w.level for w in suite) == {level: 20 for level in LEVELS}
    assert [w.level for w in suite] == sorted((w.level for w in suite), key=list(LEVELS).index)
    assert len({w.name for w in suite}) == len(suite)


def test_every_world_loads_in_the_sim_as_it_is() -> None:
    for bench in load_suite(SUITE):
        world = load_world(bench.world_file)
        assert world.name == bench.name
        (robot,) = world.robots
        assert (robot.x, robot.y, robot.yaw) == bench.start
        # the goal is on the map and the robot fits there
        assert world.blocked(*bench.goal, BURGER.footprint_radius_m) is None


def test_stored_reference_lengths_match_a_recomputation() -> None:
    for bench in load_suite(SUITE):
        grid = load_world(bench.world_file).grid  # the map as the sim reads it
        occupied = occupied_cells(grid)
        ref = reference_path(
            occupied,
            grid.resolution,
            (grid.origin[0], grid.origin[1]),
            bench.start[:2],
            bench.goal,
            bench.inflation_m,
        )
        assert ref is not None, bench.name
        assert ref.length_m == pytest.approx(bench.reference_length_m, abs=1e-3), bench.name
        assert bench.optimal_time_s == pytest.approx(bench.reference_length_m / 0.22, abs=1e-3)
        # the stored polyline is that path, and the robot's disc fits all along it
        assert len(ref.points) == len(bench.reference_path)
        for a, b in zip(ref.points, bench.reference_path, strict=True):
            assert a == pytest.approx(b, abs=1e-4)
        clear = min_clearance(occupied, grid.resolution, bench.reference_path, step_m=0.01)
        assert clear >= BURGER.footprint_radius_m, bench.name


def test_suite_md_names_the_command_that_rebuilds_the_files(tmp_path: Path) -> None:
    text = (SUITE / "SUITE.md").read_text()
    match = re.search(r"^pnav worlds generate .*$", text, re.MULTILINE)
    assert match, "SUITE.md must give the exact command"
    command = match.group(0)
    seed = int(re.search(r"--seed (\d+)", command).group(1))  # type: ignore[union-attr]
    # two worlds per level, rebuilt from the command's seed: byte for byte the shipped ones
    for level in LEVELS:
        for index in (0, 19):
            name = f"barn_{level}_{index:03d}"
            world = generate_world(level, seed * 1000 + index, name=name)
            write_world(world, tmp_path, header=world_header(command))
            for rel in (f"{name}.yaml", f"maps/{name}.yaml", f"maps/{name}.pgm"):
                assert (tmp_path / rel).read_bytes() == (SUITE / rel).read_bytes(), rel
            assert read_benchmark(SUITE / f"{name}.yaml").seed == world.seed


def test_the_suite_stays_small() -> None:
    total = sum(p.stat().st_size for p in SUITE.rglob("*") if p.is_file())
    assert total < 3 * 2**20, f"worlds/barn weighs {total / 2**20:.1f} MiB"

"""The shipped BARN-protocol suite (worlds/barn_protocol): made for the jackal model as it
ships, every world loads in the sim, its stored path is recomputed on the world as the sim
loads it (map and obstacles), and the command in SUITE.md rebuilds it byte for byte."""

from __future__ import annotations

import re
import shlex
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from common.robotmodel import load_model
from pnav.bench.nav import barn, worlds_cli
from pnav.bench.nav.search import reference_path
from pnav.bench.nav.worldfile import load_suite
from services.sim.world_spec import load_world
from tests.unit.navbench.test_barn_protocol import world_truth

pytestmark = pytest.mark.timeout(120)

SUITE = Path(__file__).resolve().parents[3] / "worlds" / "barn_protocol"


def test_the_suite_has_15_worlds_per_level_for_the_jackal() -> None:
    suite = load_suite(SUITE)
    assert Counter(w.level for w in suite) == {level: 15 for level in barn.LEVELS}
    jackal = load_model("jackal")
    for w in suite:
        assert (w.protocol, w.model, w.goal_tolerance_m, w.time_limit_s) == (
            "barn",
            "jackal",
            1.0,
            100.0,
        )
        assert (w.top_speed_mps, w.footprint_radius_m) == (
            jackal.max_linear_mps,
            jackal.footprint_radius_m,
        )
        assert w.optimal_time_s == pytest.approx(w.reference_length_m / 2.0, abs=1e-3)


def test_every_world_loads_in_the_sim_with_its_obstacles_off_the_map() -> None:
    for bench in load_suite(SUITE):
        world = load_world(bench.world_file)
        (robot,) = world.robots
        assert (robot.robot_id, robot.x, robot.y, robot.yaw) == ("r1", *bench.start)
        assert len(world.obstacles) > 5
        # the map is the walls (one 0.15 m cell, 3 pixels) and free floor inside them
        assert not world.grid.cells[3:-3, 3:-3].any(), bench.name
        assert (world.grid.cells[[0, 2, -3, -1], :] != 0).all(), bench.name
        assert world.blocked(*bench.goal, bench.footprint_radius_m) is None


def test_stored_paths_match_a_recomputation_on_the_world_as_loaded() -> None:
    for bench in load_suite(SUITE):
        truth, res = world_truth(bench.world_file)
        ref = reference_path(truth, res, (0.0, 0.0), bench.start[:2], bench.goal, bench.inflation_m)
        assert ref is not None, bench.name
        assert ref.length_m == pytest.approx(bench.reference_length_m, abs=1e-3), bench.name
        stored = np.array(bench.reference_path)
        assert np.allclose(np.array(ref.points), stored, atol=1e-3), bench.name


def test_the_command_in_suite_md_rebuilds_the_suite(tmp_path: Path) -> None:
    text = (SUITE / "SUITE.md").read_text()
    (command,) = re.findall(r"```sh\n(pnav worlds generate [^\n]+)\n```", text)
    argv = shlex.split(command)[2:]  # after "pnav worlds"
    out = argv.index("--out") + 1
    assert argv[out] == "worlds/barn_protocol"
    rebuilt = tmp_path / "worlds" / "barn_protocol"
    argv[out] = str(rebuilt)
    assert worlds_cli.main(argv) == 0
    shipped = sorted(p.relative_to(SUITE) for p in SUITE.rglob("*") if p.is_file())
    assert shipped == sorted(p.relative_to(rebuilt) for p in rebuilt.rglob("*") if p.is_file())
    for rel in shipped:
        if rel.suffix == ".md" or (rel.suffix == ".yaml" and rel.parent == Path(".")):
            # the command is recorded with the folder it was given
            want = (SUITE / rel).read_text()
            got = (rebuilt / rel).read_text().replace(str(rebuilt), "worlds/barn_protocol")
            assert got == want, rel
        else:
            assert (rebuilt / rel).read_bytes() == (SUITE / rel).read_bytes(), rel

"""The dynamic BARN protocol (``pnav worlds generate --protocol dynabarn``): the same level,
seed and robot give the same bytes; the movers cross the corridor inside the field at 0.1 to
1.0 m/s, seen by the sim and never in the map; the shipped suite (worlds/dynabarn) loads and
its SUITE.md command rebuilds it byte for byte; the report picture draws the movers' tracks."""

from __future__ import annotations

import re
import shlex
from collections import Counter
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from pnav.bench.nav import dynabarn, render, worlds_cli
from pnav.bench.nav.barn import BarnLayout
from pnav.bench.nav.dynabarn import generate_dynabarn_world
from pnav.bench.nav.dynabarnfile import write_dynabarn_world
from pnav.bench.nav.robots import resolve_model
from pnav.bench.nav.worldfile import load_suite, read_benchmark
from services.sim.world_spec import load_world

pytestmark = pytest.mark.timeout(120)

JACKAL = resolve_model("jackal")
LAYOUT = BarnLayout()
SUITE = Path(__file__).resolve().parents[3] / "worlds" / "dynabarn"


def test_same_level_seed_and_robot_give_the_same_bytes(tmp_path: Path) -> None:
    for folder in ("a", "b"):
        write_dynabarn_world(generate_dynabarn_world("hard", 7, JACKAL), tmp_path / folder)
    for rel in ("dynabarn_hard_s7.yaml", "maps/dynabarn_hard_s7.yaml", "maps/dynabarn_hard_s7.pgm"):
        assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes()
    other = generate_dynabarn_world("hard", 8, JACKAL)
    assert other.crossings != generate_dynabarn_world("hard", 7, JACKAL).crossings


def test_movers_cross_the_field_in_the_sim_world_only(tmp_path: Path) -> None:
    low, high = LAYOUT.field_y
    for level, rule in dynabarn.LEVELS.items():
        path = write_dynabarn_world(generate_dynabarn_world(level, 3, JACKAL), tmp_path)
        bench = read_benchmark(path)
        world = load_world(path)
        assert (bench.protocol, bench.time_limit_s, bench.goal_tolerance_m) == (
            "dynabarn",
            100.0,
            1.0,
        )
        assert len(world.movers) == rule.movers and bench.movers == world.movers
        assert not world.obstacles
        # the map is the walls and free floor inside them: no mover in it
        assert not world.grid.cells[3:-3, 3:-3].any()
        for m in world.movers:
            assert dynabarn.MIN_SPEED_MPS <= m.speed_mps <= rule.max_speed_mps <= 1.0
            assert m.mode == "back_and_forth" and len(m.path) == 2
            (ax, ay), (bx, by) = m.path
            assert abs(bx - ax) > 3.5  # across the corridor
            assert all(low - 1e-3 <= y <= high + 1e-3 for y in (ay, by))  # rounded to mm
            for t in np.linspace(0.0, m.period_s, 50):
                x, y, _ = m.pose_at(float(t))
                assert world.grid.occupied_near(x, y, m.radius_m) is False  # clear of walls


def test_the_shipped_suite_loads_and_its_command_rebuilds_it(tmp_path: Path) -> None:
    suite = load_suite(SUITE)
    assert Counter(w.level for w in suite) == {level: 10 for level in dynabarn.LEVELS}
    assert {(w.protocol, w.model) for w in suite} == {("dynabarn", "jackal")}
    text = (SUITE / "SUITE.md").read_text()
    (command,) = re.findall(r"```sh\n(pnav worlds generate [^\n]+)\n```", text)
    argv = shlex.split(command)[2:]  # after "pnav worlds"
    out = argv.index("--out") + 1
    assert argv[out] == "worlds/dynabarn"
    rebuilt = tmp_path / "worlds" / "dynabarn"
    argv[out] = str(rebuilt)
    assert worlds_cli.main(argv) == 0
    shipped = sorted(p.relative_to(SUITE) for p in SUITE.rglob("*") if p.is_file())
    assert shipped == sorted(p.relative_to(rebuilt) for p in rebuilt.rglob("*") if p.is_file())
    for rel in shipped:
        if rel.suffix == ".md" or (rel.suffix == ".yaml" and rel.parent == Path(".")):
            want = (SUITE / rel).read_text()
            got = (rebuilt / rel).read_text().replace(str(rebuilt), "worlds/dynabarn")
            assert got == want, rel
        else:
            assert (rebuilt / rel).read_bytes() == (SUITE / rel).read_bytes(), rel


def colours_of(image: npt.NDArray[np.uint8]) -> set[tuple[int, ...]]:
    return {tuple(int(v) for v in c) for c in image.reshape(-1, 3)}


def test_the_report_picture_draws_the_movers_tracks(tmp_path: Path) -> None:
    bench = read_benchmark(
        write_dynabarn_world(generate_dynabarn_world("easy", 2, JACKAL), tmp_path)
    )
    grid = bench.grid()
    image = render.draw_run(bench, scale=4)
    map_h, per_m = grid.height * 4, 4 / grid.resolution

    def at(x: float, y: float) -> tuple[int, ...]:
        row = int(map_h - (y - grid.origin[1]) * per_m)
        return tuple(int(v) for v in image[row, int((x - grid.origin[0]) * per_m)])

    for m in bench.movers:
        (ax, ay), (bx, by) = m.path
        # a quarter along (clear of the reference path, up the middle) is on the track's
        # centre line; most of a radius off it, in the band
        mx, my = ax + (bx - ax) / 4, ay + (by - ay) / 4
        assert at(mx, my) in (render.MOVER, render.MOVER_BAND)
        assert at(mx, my + 0.8 * m.radius_m) in (render.MOVER_BAND, render.MOVER)
        x, y, _ = m.pose_at(0.0)
        assert at(x, y) == render.MOVER  # its body where it starts
    legend = colours_of(image[map_h:])
    assert render.MOVER in legend and render.MOVER_BAND in legend
    # a world without movers has neither colour
    plain = render.draw_world(np.zeros((10, 10), dtype=bool), 0.1, (0.0, 0.0), legend=True)
    assert render.MOVER not in colours_of(plain) and render.MOVER_BAND not in colours_of(plain)

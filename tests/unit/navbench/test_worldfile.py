"""World files: what is written reads back, bad files fail naming themselves, and the
``pnav worlds generate`` command writes a suite."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from common.errors import WorldError
from pnav.bench.nav.generator import generate_world
from pnav.bench.nav.worldfile import load_suite, read_benchmark, write_world
from pnav.bench.nav.worlds_cli import main
from services.sim.world_spec import load_world

pytestmark = pytest.mark.timeout(30)


def test_written_world_reads_back(tmp_path: Path) -> None:
    world = generate_world("medium", 5, name="w5")
    path = write_world(world, tmp_path, header="line one\n\nline three")
    assert path == tmp_path / "w5.yaml"
    assert path.read_text().startswith("# line one\n#\n# line three\nname: w5\n")
    bench = read_benchmark(path)
    assert (bench.name, bench.level, bench.seed) == ("w5", "medium", 5)
    assert bench.map_file == tmp_path / "maps" / "w5.yaml"
    assert bench.start == pytest.approx(world.start)
    assert bench.goal == world.goal
    assert bench.goal_tolerance_m == 0.3
    assert bench.reference_length_m == pytest.approx(world.reference.length_m, abs=1e-4)
    assert len(bench.reference_path) == len(world.reference.points)
    assert bench.optimal_time_s == pytest.approx(world.reference.length_m / 0.22, abs=1e-3)
    assert bench.time_limit_s % 10 == 0 and bench.time_limit_s >= 8 * bench.optimal_time_s
    assert bench.fill_ratio == pytest.approx(world.fill_ratio, abs=1e-4)
    assert bench.difficulty.tortuosity == pytest.approx(world.difficulty.tortuosity, abs=1e-4)
    assert bench.generator["fill_probability"] == world.rule.fill_probability
    assert bench.inflation_m == pytest.approx(0.155)
    assert (bench.grid().cells == 100).sum() == world.occupied.sum()
    sim_world = load_world(path)
    assert sim_world.grid.width == world.occupied.shape[1]


def test_bad_benchmark_files_name_themselves(tmp_path: Path) -> None:
    plain = tmp_path / "plain.yaml"
    plain.write_text(yaml.safe_dump({"name": "plain", "map": "m.yaml", "robots": []}))
    with pytest.raises(WorldError, match=r"plain\.yaml.*not a benchmark world"):
        read_benchmark(plain)
    with pytest.raises(WorldError, match="not found"):
        read_benchmark(tmp_path / "missing.yaml")
    good = write_world(generate_world("easy", 1, name="good"), tmp_path)
    doc = yaml.safe_load(good.read_text())
    for key, value, message in (
        ("goal", [1.0], "benchmark.goal must be 2 numbers"),
        ("reference_path_length_m", "long", "reference_path_length_m"),
        ("reference_path", [[0, 0]], "at least 2 points"),
        ("difficulty", {"tortuosity": 1.0}, "difficulty is incomplete"),
        ("format", 2, "format"),
    ):
        broken = {**doc, "benchmark": {**doc["benchmark"], key: value}}
        bad = tmp_path / f"bad_{key}.yaml"
        bad.write_text(yaml.safe_dump(broken))
        with pytest.raises(WorldError, match=message) as err:
            read_benchmark(bad)
        assert str(bad) in str(err.value)
    with pytest.raises(WorldError, match="no benchmark world"):
        load_suite(tmp_path / "maps")
    with pytest.raises(WorldError, match="no such suite"):
        load_suite(tmp_path / "nowhere")


def test_generate_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "suite"
    status = main(["generate", "--out", str(out), "--count", "2", "--seed", "4", "--png"])
    assert status == 0
    printed = capsys.readouterr().out
    assert "barn_hard_001" in printed and "wrote 6 worlds" in printed
    suite = load_suite(out)
    assert [w.name for w in suite] == [
        f"barn_{level}_{i:03d}" for level in ("easy", "medium", "hard") for i in range(2)
    ]
    assert suite[1].seed == 4001
    assert len(list((out / "preview").glob("*.png"))) == 6
    md = (out / "SUITE.md").read_text()
    assert f"pnav worlds generate --out {out} --count 2 --seed 4" in md
    assert "| hard (2) |" in md
    # writing a smaller suite on top warns about the worlds it leaves behind
    assert main(["generate", "--out", str(out), "--count", "1", "--levels", "easy"]) == 0
    assert "also holds other benchmark worlds: barn_easy_001.yaml" in capsys.readouterr().out


def test_generate_command_refuses_bad_options(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["generate", "--out", str(tmp_path), "--levels", "easy,insane"]) == 2
    assert "unknown insane" in capsys.readouterr().err
    assert main(["generate", "--out", str(tmp_path), "--count", "0"]) == 2
    assert not list(tmp_path.iterdir())

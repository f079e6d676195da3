"""``python -m pnav.bench.chain``: the design's floor, the stack's path with no rules."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pnav.bench import chain


def test_every_sample_is_committed_three_times_and_comes_back_stamped(tmp_path: Path) -> None:
    out = tmp_path / "chain.json"
    assert chain.main(["--robots", "2", "--seconds", "1", "--json", str(out)]) == 0
    figures = json.loads(out.read_text())
    run = figures["runs"][0]
    assert run["robots"] == 2 and run["sent"] == 40
    # a sample still on its way when the benchmark stops listening is its own cut
    assert run["samples"] >= run["sent"] - 2
    assert 0 < run["p50_ms"] <= run["p95_ms"] <= run["p99_ms"]
    # sensor -> row (bridge), row -> recommendation (planner), recommendation -> command
    # (decision): each sample, warm-up included, is a row in each
    rows = figures["rows"]
    assert set(rows) == {"chain_row", "chain_rec", "chain_command"}
    assert rows["chain_row"] >= rows["chain_rec"] >= rows["chain_command"] >= run["samples"]
    roles = {"sim", "bridge", "planner", "decision", "postgres", "router"}
    assert set(run["cpu_pct_by_role"]) == roles
    assert all(v >= 0 for v in run["cpu_pct_by_role"].values())


@pytest.mark.parametrize("argv", [["--robots", "one"], ["--robots", "0"], ["--seconds", "0"]])
def test_bad_arguments_are_refused_with_a_usage_line(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as ended:
        chain.main(argv)
    assert ended.value.code == 2
    assert "usage:" in capsys.readouterr().err

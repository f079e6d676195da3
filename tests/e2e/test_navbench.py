"""`pnav bench nav` as a user runs it: the whole stack in one easy benchmark world, through
the command line, with --json and --report."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]

ROOT = Path(__file__).resolve().parents[2]


def test_bench_nav_runs_one_easy_world_and_writes_json_and_report(tmp_path: Path) -> None:
    env = dict(os.environ)
    env.pop("PNAV_DATABASE_URL", None)  # the bench starts its own stack per episode
    command = [sys.executable, "-m", "pnav", "bench", "nav", "--levels", "easy", "--worlds", "1"]
    command += ["--combos", "GOTO_AVOID/turn_then_move", "--json", str(tmp_path / "nav.json")]
    command += ["--report", str(tmp_path / "report")]
    done = subprocess.run(
        command,
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=110,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "1/1" in done.stderr  # the progress bar reached the end
    assert "stack: per combo" in done.stdout

    doc = json.loads((tmp_path / "nav.json").read_text())
    assert doc["worlds"] == ["barn_easy_000"] and doc["combos"] == ["GOTO_AVOID/turn_then_move"]
    (run,) = doc["runs"]
    assert (run["world"], run["combo"], run["mode"], run["seed"]) == (
        "barn_easy_000",
        "GOTO_AVOID/turn_then_move",
        "stack",
        0,
    )
    # an easy world: the stack gets there, without touching anything, well within the limit
    assert (run["outcome"], run["end"], run["collision_count"]) == ("success", "goal", 0)
    assert run["final_distance_m"] <= 0.3 and 0 < run["time_s"] < 100
    assert 0.5 < run["spl"] <= 1.0 and 0.125 <= run["score"] <= 0.5
    first, last = run["trajectory"][0], run["trajectory"][-1]
    assert (
        math.dist(first[1:], (2.4, 0.6)) < 0.1 and math.dist(last[1:], (2.4, 6.0)) <= 0.301
    )  # JSON: mm
    assert run["cpu_s"] > 0 and 0 < run["run_wall_s"] < run["wall_s"]
    roles = set(run["cpu_by_role"])
    assert {"sim", "postgres", "bridge"} <= roles
    # one process each, or (the default on a machine of few cores) one host runs them
    assert {"planner", "decision"} <= roles or "host" in roles
    assert run["gate_timeouts"] is not None
    summary = doc["summary"]["stack"]["by_combo"]["GOTO_AVOID/turn_then_move"]
    assert summary["runs"] == 1 and summary["success_rate"] == 1.0
    assert doc["cost"]["GOTO_AVOID/turn_then_move"]["stack"]["cpu_per_sim_s"] > 0

    report = tmp_path / "report"
    png = report / "barn_easy_000__GOTO_AVOID-turn_then_move.png"
    assert run["png"] == png.name and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    readme = (report / "README.md").read_text()
    assert f"[{png.name}]({png.name})" in readme and "| success | goal |" in readme
    assert (Path(run["log_dir"]) / "sim.log").is_file()
    assert Path(run["log_dir"]).parent == report / "logs"

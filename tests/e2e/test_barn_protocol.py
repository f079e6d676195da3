"""`pnav bench nav` on a BARN-protocol world as a user runs it: the whole stack, the field's
obstacles only in the sim (the planner's map has the walls alone), the run ending at BARN's
1 m from the goal and scored with the world's model (OT at the jackal's 2 m/s)."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.slow, pytest.mark.timeout(240)]

ROOT = Path(__file__).resolve().parents[2]


def test_bench_nav_runs_an_easy_barn_protocol_world_to_within_1_m(tmp_path: Path) -> None:
    env = dict(os.environ)
    env.pop("PNAV_DATABASE_URL", None)  # the bench starts its own stack per episode
    command = [sys.executable, "-m", "pnav", "bench", "nav", "--suite", "worlds/barn_protocol"]
    command += ["--levels", "easy", "--worlds", "1", "--combos", "GOTO_AVOID/turn_then_move"]
    command += ["--json", str(tmp_path / "nav.json")]
    done = subprocess.run(
        command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=230, check=False
    )
    assert done.returncode == 0, done.stdout + done.stderr

    doc = json.loads((tmp_path / "nav.json").read_text())
    assert doc["suite"] == "worlds/barn_protocol" and doc["worlds"] == ["barn_easy_000"]
    (run,) = doc["runs"]
    # the easiest world of the suite: through the unmapped field, untouched, in BARN's 100 s
    assert (run["outcome"], run["end"], run["collision_count"]) == ("success", "goal", 0)
    assert 0 < run["time_s"] <= 100.0
    # the run ends at the first reading within 1 m of the goal (BARN's rule), not 0.3 m
    assert 0.9 < run["final_distance_m"] <= 1.0
    last = run["trajectory"][-1]
    assert math.dist(last[1:], (2.4, 10.7)) <= 1.001  # the goal: 10 m ahead of (2.4, 0.7)
    # scored at the jackal's top speed: OT = L / 2 m/s, score = OT / clip(T, 2 OT, 8 OT)
    length = run["reference_length_m"]
    ot = length / 2.0
    assert run["optimal_time_s"] == pytest.approx(ot, abs=1e-3)
    clipped = min(max(run["time_s"], 2 * ot), 8 * ot)
    assert run["score"] == pytest.approx(ot / clipped, abs=1e-3)

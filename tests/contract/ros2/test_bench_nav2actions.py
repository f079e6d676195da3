"""pnav.bench.nav2_action_cost runs its round trips to the end (what it measures, not how fast)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pnav.bench import nav2_action_cost

pytestmark = pytest.mark.slow


def test_the_bench_takes_cancels_and_ends_every_goal(tmp_path: Path) -> None:
    out = tmp_path / "nav2.json"
    assert nav2_action_cost.main(["--goals", "3", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["goals"] == 3
    for step in nav2_action_cost.STEPS:
        figures = result[step]
        assert 0 < figures["median"] <= figures["p95"] <= figures["max"]

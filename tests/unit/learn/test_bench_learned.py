"""``python -m pnav.bench.learned``: the inference benchmark decides every scene set it
names with both dwa and learned_drive (it once unpacked dwa's (scan, odom, path) scenes as
pairs and crashed before timing anything)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from common.errors import UsageError
from pnav.bench import learned


@pytest.mark.parametrize("scene_set", ["default", "barn", "barn_box"])
def test_every_set_is_timed_for_both(scene_set: str, tmp_path: Path) -> None:
    out = tmp_path / "figures.json"
    argv = ["--scenes", "3", "--repeat", "1", "--set", scene_set, "--json", str(out)]
    assert learned.main(argv) == 0
    figures = json.loads(out.read_text())
    assert figures["set"] == scene_set
    assert figures["dwa_cpu_ms_per_decision"] > 0
    assert figures["learned_ms_per_decision"] > 0
    share = figures["learned_ms_per_decision"] / figures["dwa_ms_per_decision"]
    assert figures["learned_share_of_dwa"] == pytest.approx(share, abs=1e-3)
    # its check's work is reported with its cost: a share, and at least the proposal checked
    assert 0.0 <= figures["proposal_passed_share"] <= 1.0
    assert figures["candidates_checked_mean"] >= 1.0


def test_a_directory_that_is_no_kept_database_is_refused(tmp_path: Path) -> None:
    with pytest.raises(UsageError, match="not a Postgres data directory"):
        learned.main(["--db-dir", str(tmp_path)])

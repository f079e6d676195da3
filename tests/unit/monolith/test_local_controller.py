"""GOTO_FAST in the monolith: the dwa local controller (found through its entry point) on
the planner's planned_path rows, over the in-memory contract, on real worlds."""

from __future__ import annotations

from pathlib import Path

import pytest

from pnav.bench.nav.stack_episode import Combo, Episode
from pnav.bench.nav.worldfile import read_benchmark
from pnav.monolith.monolith_episode import run_monolith_episode

ROOT = Path(__file__).resolve().parents[3]
FAST = Combo("GOTO_FAST", "turn_then_move")
AVOID = Combo("GOTO_AVOID", "turn_then_move")


def episode(name: str, combo: Combo) -> Episode:
    path = ROOT / "worlds" / "barn" / f"{name}.yaml"
    bench = read_benchmark(path)
    return Episode(path, bench.goal, combo, bench.time_limit_s)


@pytest.mark.slow
def test_goto_fast_solves_a_hard_barn_world_with_the_burger_no_slower_than_goto_avoid() -> None:
    fast = run_monolith_episode(episode("barn_hard_003", FAST))
    assert fast.end == "goal" and fast.collisions == []
    assert set(fast.decided_by) <= {"dwa", "safety_stop", "recovery", ""}
    assert fast.decided_by["dwa"] > 0 and "turn_then_move" not in fast.recommended_by
    avoid = run_monolith_episode(episode("barn_hard_003", AVOID))
    assert avoid.end == "goal"
    assert fast.time_s <= avoid.time_s

"""The cheap cases of ``pnav bench faults`` (docs/BENCHMARKS.md, "Faults"), each one mission
of the benchmark itself on the warehouse world: the stack launched as ``pnav up`` does, r1
sent across, the fault injected once it has driven a metre, the mission followed to its end.
Every target of the benchmark is asserted: a safe outcome, no collision, at most 0.15 m
driven after the last command, no committed row lost."""

from __future__ import annotations

from pathlib import Path

import pytest

from pnav.bench.faults.catalogue import mission_goal, select
from pnav.bench.faults.report import misses
from pnav.bench.faults.trial import Result, run_trial
from pnav.bench.faults.world import bad_goals

pytestmark = pytest.mark.timeout(240)

RATE = "2"


async def trial(name: str, tmp_path: Path) -> Result:
    (fault,) = select(name)
    world, goal = mission_goal("warehouse")
    result = await run_trial(fault, world, goal, bad_goals(world), RATE, tmp_path / "logs")
    print(result)
    return result


async def test_a_rogue_full_speed_recommendation_never_drives_into_anything(
    tmp_path: Path,
) -> None:
    r = await trial("rogue-priority", tmp_path)
    assert r.outcome == "reached"
    # the safety band is for stops: the database refused priority 1000 for a drive
    assert any("priority 1000 refused by the database" in n for n in r.notes), r.notes
    assert r.collisions == 0 and r.contacts == 0
    assert misses(r) == []


async def test_a_goal_of_nan_is_refused_at_the_door_and_the_mission_goes_on(
    tmp_path: Path,
) -> None:
    r = await trial("goal-nan", tmp_path)
    assert r.outcome.startswith("refused (exit 2): pnav goal: argument x: must be a finite")
    assert r.outcome.endswith("; then reached")
    assert misses(r) == []


async def test_a_goal_inside_a_rack_ends_the_mission_as_failed_with_its_reason(
    tmp_path: Path,
) -> None:
    r = await trial("goal-in-obstacle", tmp_path)
    assert r.outcome == "failed: goal (2.50, 2.45) is inside an obstacle on the map"
    assert misses(r) == []


async def test_a_controller_killed_mid_mission_is_restarted_and_the_goal_reached(
    tmp_path: Path,
) -> None:
    r = await trial("kill-controller", tmp_path)
    assert r.outcome == "reached"
    assert r.restart_s is not None and r.recovered_s is not None
    assert r.rows_checked > 0 and r.rows_lost == {}
    assert misses(r) == []


async def test_params_nested_500_deep_are_refused_and_the_dashboard_still_serves(
    tmp_path: Path,
) -> None:
    r = await trial("deep-params", tmp_path)
    assert r.outcome.startswith("refused: POST 400 "), r.outcome
    assert "INSERT refused (strategy_params_bounded)" in r.outcome
    assert r.outcome.endswith("; then reached")
    assert misses(r) == []


async def test_a_dns_rebinding_page_is_refused_for_goals_and_websockets(tmp_path: Path) -> None:
    r = await trial("dns-rebinding", tmp_path)
    assert r.outcome == (
        "refused: goal POST 403; websocket 403; https-origin websocket 403; then reached"
    ), r.outcome
    assert misses(r) == []

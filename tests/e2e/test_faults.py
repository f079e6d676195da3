"""The cheap cases of ``pnav bench faults`` (docs/BENCHMARKS.md, "Faults"), each one mission
of the benchmark itself on the warehouse world: the stack launched as ``pnav up`` does, r1
sent across, the fault injected once it has driven a metre, the mission followed to its end.
Every target of the benchmark is asserted: a safe outcome, no collision, at most 0.15 m
driven after the last command, no committed row lost, no breach."""

from __future__ import annotations

from pathlib import Path

import pytest

from pnav.bench.faults.bad_goals import bad_goals
from pnav.bench.faults.catalogue import mission_goal, select
from pnav.bench.faults.trial import Result, run_trial
from pnav.bench.faults.verdict import misses

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


async def test_forged_row_images_cite_nothing_and_move_nothing(tmp_path: Path) -> None:
    r = await trial("forged-images", tmp_path)
    assert r.outcome == "reached", r.notes
    assert any("through their own credentials" in n for n in r.notes), r.notes
    # the readers dropped every forgery: no command cites one, no cmd_vel relays one
    assert any(
        n == "command2robot rows citing a nonexistent recommendation: 0; "
        "cmd_vel sent from a forged command: 0"
        for n in r.notes
    ), r.notes
    assert misses(r) == []


async def test_spoofed_odometry_is_refused_by_the_router_and_never_stored(
    tmp_path: Path,
) -> None:
    r = await trial("spoof-odom", tmp_path)
    assert "the router refused the session of a client without a password" in r.notes, r.notes
    assert any(n.endswith("odometry messages forged as user") for n in r.notes), r.notes
    assert r.forged_believed == 0  # people's identity may not put sensor messages
    assert r.outcome == "reached"  # where r1 truly is, by the sim's own odometry
    assert misses(r) == []


async def test_a_cmd_vel_forged_as_people_never_reaches_the_sim(tmp_path: Path) -> None:
    r = await trial("forged-cmd-vel", tmp_path)
    assert any(n.endswith("cmd_vel forged as user, straight to the sim") for n in r.notes)
    assert r.forged_believed == 0, r.notes  # the sim's trace: none applied
    assert r.outcome == "reached" and r.collisions == 0 and r.contacts == 0
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


async def test_a_lease_theft_by_people_is_refused_and_moves_no_robot(tmp_path: Path) -> None:
    r = await trial("lease-theft", tmp_path)
    assert r.outcome == "reached"
    assert r.breaches == [], r.breaches  # every call refused, r1's owners never changed
    assert any("lock and lease calls refused" in n for n in r.notes), r.notes
    assert misses(r) == []


async def test_people_locking_strategy_and_goal_stall_no_robot(tmp_path: Path) -> None:
    r = await trial("table-lock", tmp_path)
    assert r.outcome == "reached"
    assert r.collisions == 0 and r.contacts == 0
    assert r.breaches == [], r.breaches  # safety_stop ran while the tables were held
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

"""Run metrics: outcome classification, path length, SPL, the BARN score, summaries; every
expected value is worked out by hand in the comments."""

from __future__ import annotations

import json
import math

import pytest

from pnav.bench.nav.scores import (
    RunResult,
    barn_score,
    default_time_limit,
    evaluate_run,
    mean_spl,
    optimal_time,
    path_length,
    spl,
    summarize,
    summarize_by,
)

pytestmark = pytest.mark.timeout(20)

GOAL = (0.0, 5.0)


def run(
    end: tuple[float, float],
    *,
    elapsed_s: float = 30.0,
    time_limit_s: float = 100.0,
    collisions: tuple[tuple[float, float], ...] | list[tuple[float, float]] = (),
) -> RunResult:
    """A straight run from (0, 0) to ``end``; reference 5 m (OT = 5 / 0.22 = 22.7 s)."""
    return evaluate_run(
        [(0.0, 0.0), end],
        goal=GOAL,
        elapsed_s=elapsed_s,
        time_limit_s=time_limit_s,
        reference_length_m=5.0,
        collisions=collisions,
    )


def test_path_length() -> None:
    assert path_length([(0, 0), (3, 4), (3, 0)]) == pytest.approx(9.0)  # 5 + 4
    assert path_length([(1, 1)]) == 0.0
    assert path_length([]) == 0.0


def test_spl_by_hand() -> None:
    assert spl(True, 10.0, 12.5) == pytest.approx(0.8)  # 10 / max(10, 12.5)
    assert spl(True, 10.0, 20.0) == pytest.approx(0.5)
    # stopping inside the tolerance before the goal: shorter than L, SPL is capped at 1
    assert spl(True, 10.0, 9.8) == pytest.approx(1.0)
    assert spl(False, 10.0, 10.0) == 0.0
    with pytest.raises(ValueError):
        spl(True, 0.0, 1.0)


def test_score_by_hand_and_its_clipping() -> None:
    # L = 2.2 m at 0.22 m/s: OT = 10 s; the time is clipped to [20 s, 80 s]
    assert optimal_time(2.2) == pytest.approx(10.0)
    assert barn_score(True, 2.2, 40.0) == pytest.approx(0.25)  # 10 / 40, not clipped
    assert barn_score(True, 2.2, 15.0) == pytest.approx(0.5)  # faster than 2 OT: 10 / 20
    assert barn_score(True, 2.2, 20.0) == pytest.approx(0.5)
    assert barn_score(True, 2.2, 5.0) == pytest.approx(0.5)  # even faster than OT
    assert barn_score(True, 2.2, 100.0) == pytest.approx(0.125)  # slower than 8 OT: 10 / 80
    assert barn_score(False, 2.2, 40.0) == 0.0
    # the first challenge's clip [4 OT, 8 OT]: 10 / 40
    assert barn_score(True, 2.2, 15.0, clip=(4.0, 8.0)) == pytest.approx(0.25)
    # another top speed: OT = 2.2 / 0.5 = 4.4 s; 4.4 / 20
    assert barn_score(True, 2.2, 20.0, top_speed_mps=0.5) == pytest.approx(0.22)


def test_default_time_limit_is_8_ot_rounded_up_to_10_s() -> None:
    assert default_time_limit(5.5) == 200.0  # OT 25 s, 8 OT = 200 s
    assert default_time_limit(5.6) == 210.0  # OT 25.45 s, 8 OT = 203.6 s


def test_goal_tolerance_edges() -> None:
    near = run((0.0, 5.0 - 0.29))
    assert near.outcome == "success" and near.success
    assert near.final_distance_m == pytest.approx(0.29)
    assert near.path_length_m == pytest.approx(4.71)
    assert near.spl == pytest.approx(1.0)  # 4.71 < 5: capped
    assert near.score == pytest.approx(0.5)  # 30 s < 2 OT = 45.45 s
    far = run((0.0, 5.0 - 0.31))
    assert not far.success and far.outcome == "stopped"  # ended early, nowhere near
    assert far.spl == 0.0 and far.score == 0.0
    exact = run((0.3, 5.0))
    assert exact.success  # "within 0.3 m" includes 0.3 m


def test_collision_overrides_success() -> None:
    result = run((0.0, 5.0), collisions=[(0.0, 2.0)])
    assert result.outcome == "collision"
    assert result.collision and not result.success and not result.timeout
    assert result.spl == 0.0 and result.score == 0.0 and result.collision_count == 1
    # also over a timeout
    late = run((0.0, 1.0), elapsed_s=100.0, collisions=[(0.0, 1.0)])
    assert late.outcome == "collision" and not late.timeout


def test_timeout() -> None:
    never = run((0.0, 3.0), elapsed_s=100.0)
    assert never.outcome == "timeout" and never.timeout and not never.success
    too_late = run((0.0, 5.0), elapsed_s=100.5)  # arrived, but after the limit
    assert too_late.outcome == "timeout" and not too_late.success
    just_in_time = run((0.0, 5.0), elapsed_s=100.0)
    assert just_in_time.success
    assert just_in_time.score == pytest.approx(optimal_time(5.0) / 100.0)  # within [2, 8] OT


def test_the_run_ends_at_arrival() -> None:
    # past the goal and on: only the way to the first point within 0.3 m counts
    trajectory = [(0.0, 0.0), (0.0, 4.0), (0.0, 4.8), (0.0, 6.0), (3.0, 6.0)]
    times = [0.0, 20.0, 24.0, 30.0, 45.0]
    result = evaluate_run(
        trajectory,
        goal=GOAL,
        elapsed_s=45.0,
        time_limit_s=100.0,
        reference_length_m=4.0,
        times=times,
    )
    assert result.success
    assert result.time_s == 24.0  # the arrival, not the end of the recording
    assert result.path_length_m == pytest.approx(4.8)
    assert result.spl == pytest.approx(4.0 / 4.8)
    # OT = 4 / 0.22 = 18.18 s; 24 s is below 2 OT = 36.4 s
    assert result.score == pytest.approx(0.5)
    with pytest.raises(ValueError):
        evaluate_run(
            trajectory, goal=GOAL, elapsed_s=1, time_limit_s=9, reference_length_m=4, times=[0]
        )
    with pytest.raises(ValueError):
        evaluate_run([], goal=GOAL, elapsed_s=1, time_limit_s=9, reference_length_m=4)


def test_a_slow_success_scores_between_the_clips() -> None:
    # OT = 5 / 0.22 = 22.73 s; 120 s lies within [2 OT, 8 OT] = [45.5, 181.8] s: 22.73 / 120
    result = run((0.0, 5.0), elapsed_s=120.0, time_limit_s=200.0)
    assert result.score == pytest.approx(5.0 / 0.22 / 120.0)
    assert result.optimal_time_s == pytest.approx(22.7272727)


def test_summary_by_hand() -> None:
    ok = run((0.0, 5.0), elapsed_s=30.0)  # SPL 1 (driven 5 m), score 0.5
    detour = evaluate_run(
        [(0.0, 0.0), (3.0, 4.0), (0.0, 5.0)],  # 5 + sqrt(10) = 8.1623 m
        goal=GOAL,
        elapsed_s=60.0,
        time_limit_s=100.0,
        reference_length_m=5.0,
    )
    crash = run((0.0, 2.0), elapsed_s=10.0, collisions=[(0.0, 2.0)])
    slow = run((0.0, 1.0), elapsed_s=100.0)
    summary = summarize([ok, detour, crash, slow])
    assert (summary.runs, summary.successes, summary.collisions, summary.timeouts) == (4, 2, 1, 1)
    assert summary.stopped == 0
    assert summary.success_rate == 0.5
    assert summary.collision_rate == 0.25 and summary.timeout_rate == 0.25
    detour_spl = 5.0 / (5.0 + math.sqrt(10.0))
    assert summary.mean_spl == pytest.approx((1.0 + detour_spl) / 4)
    # detour: OT 22.73 s, 60 s within [45.45, 181.8] s: 22.73 / 60
    assert summary.mean_score == pytest.approx((0.5 + 5.0 / 0.22 / 60.0) / 4)
    assert summary.mean_time_s == pytest.approx((30 + 60 + 10 + 100) / 4)
    assert summary.mean_success_time_s == pytest.approx(45.0)
    assert summary.mean_success_path_length_m == pytest.approx((5.0 + 5.0 + 10**0.5) / 2)
    assert mean_spl([ok, crash]) == pytest.approx(0.5)
    none_won = summarize([crash, slow])
    assert none_won.mean_success_time_s is None and none_won.mean_spl == 0.0
    with pytest.raises(ValueError):
        summarize([])


def test_summarize_by_and_json() -> None:
    ok = run((0.0, 5.0))
    crash = run((0.0, 2.0), collisions=[(0.0, 2.0)])
    groups = summarize_by([("easy", ok), ("hard", crash), ("easy", crash)])
    assert list(groups) == ["easy", "hard"]
    assert groups["easy"].runs == 2 and groups["easy"].success_rate == 0.5
    assert groups["hard"].success_rate == 0.0
    doc = json.loads(json.dumps({"run": ok.to_json(), "summary": groups["easy"].to_json()}))
    assert doc["run"]["outcome"] == "success" and doc["run"]["spl"] == 1.0
    assert doc["summary"]["mean_success_time_s"] == 30.0
    assert doc["summary"]["mean_success_path_length_m"] == 5.0

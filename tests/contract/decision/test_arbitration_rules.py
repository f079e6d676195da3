"""Arbitration (services.decision.arbitration), without I/O."""

from __future__ import annotations

import math

from common.contract.recommendations import Recommendation
from services.decision.arbitration import (
    NO_LIVE_RECOMMENDATION,
    Issued,
    decide_robot,
    decide_system,
    explain,
    winner,
)


def rec(
    rid: int,
    source: str,
    priority: int,
    linear: float = 0.0,
    angular: float = 0.0,
    reason: str = "",
    kind: str = "robot",
    command: str | None = None,
    treated_by: int | None = None,
) -> Recommendation:
    return Recommendation(
        "r1", kind, source, priority, linear, angular, command, 0.0, math.inf, {}, reason,
        id=rid, treated_by=treated_by,
    )  # fmt: skip


def test_highest_priority_then_newest() -> None:
    recs = [rec(1, "a", 10), rec(2, "b", 50), rec(3, "c", 50), rec(4, "d", 5)]
    assert winner(recs).id == 3


def test_the_reason_names_each_other_source_once() -> None:
    recs = [
        rec(1, "turn_then_move", 10),
        rec(2, "turn_then_move", 10),
        rec(3, "avoid_left", 50),
        rec(4, "safety_stop", 100, reason="obstacle 0.12 m ahead"),
        rec(5, "safety_stop", 100, reason="obstacle 0.10 m ahead"),
    ]
    assert explain(winner(recs), recs) == (
        "safety_stop (priority 100) over avoid_left (50), turn_then_move (10): "
        "obstacle 0.10 m ahead"
    )
    assert explain(recs[0], recs[:1]) == "turn_then_move (priority 10) unopposed"


def test_reissue_only_on_change_or_after_a_tenth_of_a_second() -> None:
    live = [rec(7, "turn_then_move", 10, 0.2, 0.0)]
    first = decide_robot("r1", live, None, 10.0)
    assert first is not None and first.recommendation_id == 7 and first.considered_ids == (7,)
    last = Issued(1, 10.0, 0.2, 0.0, 7, "turn_then_move")
    assert decide_robot("r1", live, last, 10.05) is None
    assert decide_robot("r1", live, last, 10.1) is not None
    assert decide_robot("r1", live, last, 3.0) is not None  # the sim restarted
    newer = [*live, rec(8, "turn_then_move", 10, 0.2, 0.0)]
    assert decide_robot("r1", newer, last, 10.01) is not None  # a new winner


def test_one_stop_when_nothing_is_live() -> None:
    moving = Issued(1, 10.0, 0.2, 0.0, 7, "turn_then_move")
    stop = decide_robot("r1", [], moving, 10.6)
    assert stop is not None
    assert (stop.linear_mps, stop.angular_rps, stop.recommendation_id) == (0.0, 0.0, None)
    assert stop.reason == NO_LIVE_RECOMMENDATION
    stopped = Issued(2, 10.6, 0.0, 0.0, None, None)
    assert decide_robot("r1", [], stopped, 11.0) is None
    assert decide_robot("r1", [], None, 11.0) is None  # never commanded: nothing to stop


def test_a_system_winner_is_sent_once() -> None:
    save = rec(1, "battery_check", 60, kind="system", command="CMD_BATTSAVE")
    resume = rec(2, "charge_complete", 50, kind="system", command="CMD_RESUME")
    decision = decide_system("r1", [save, resume], 10.0)
    assert decision is not None
    assert (decision.command, decision.recommendation_id, decision.considered_ids) == (
        "CMD_BATTSAVE",
        1,
        (1, 2),
    )
    treated = rec(1, "battery_check", 60, kind="system", command="CMD_BATTSAVE", treated_by=9)
    assert decide_system("r1", [treated, resume], 10.1) is None
    assert decide_system("r1", [], 10.1) is None

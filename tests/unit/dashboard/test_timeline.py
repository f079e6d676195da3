"""The timeline keeps one event per row and state, in time order, bounded."""

from __future__ import annotations

from datetime import UTC, datetime

from services.dashboard.timeline import Timeline, command_event, goal_event, strategy_event

T0 = datetime(2026, 1, 1, 12, 0, tzinfo=UTC)


def goal(status: str, reason: str | None = None) -> dict[str, object]:
    return {"id": 4, "robot_id": "r1", "x": 1.0, "y": 2.5, "status": status, "reason": reason}


def test_a_goal_row_read_twice_is_one_event_and_its_end_another() -> None:
    timeline = Timeline()
    assert timeline.add(goal_event({**goal("active"), "created_at": T0}))
    assert not timeline.add(goal_event({**goal("active"), "created_at": T0}))
    failed = goal_event({**goal("failed", "no path"), "created_at": T0})
    assert timeline.add(failed)
    assert failed["text"] == "goal 4 (1.00, 2.50) failed: no path"
    assert [e["key"] for e in timeline.take_fresh()] == ["goal:4:active", "goal:4:failed"]
    assert timeline.take_fresh() == []


def test_a_command_says_what_was_asked_then_the_verdict_and_why() -> None:
    row = {
        "id": 7,
        "robot_id": "r1",
        "command": "SET_STRATEGY",
        "argument": "IDLE",
        "status": "pending",
        "reason": None,
        "created_at": T0,
        "treated_at": None,
    }
    assert command_event("user_command", row)["text"] == "user: SET_STRATEGY IDLE"
    treated = {**row, "status": "rejected", "reason": "unknown strategy"}
    event = command_event("user_command", treated)
    assert event["text"] == "user: SET_STRATEGY IDLE rejected: unknown strategy"
    system = {**row, "argument": None, "command": "CMD_BATTSAVE", "status": "accepted"}
    system |= {"status_reason": "GOTO_AVOID -> CHARGE"}
    assert command_event("system_command", system)["text"] == (
        "system: CMD_BATTSAVE accepted: GOTO_AVOID -> CHARGE"
    )


def test_seeded_events_are_in_time_order_and_not_fresh_and_the_oldest_go_first() -> None:
    timeline = Timeline(keep=2)
    rows = [
        {"robot_id": "r1", "strategy_code": code, "resume_code": None, "source": "user"}
        | {"command_id": i, "updated_at": T0.replace(minute=i)}
        for i, code in [(3, "IDLE"), (1, "GOTO_AVOID"), (2, "CHARGE")]
    ]
    timeline.seed([strategy_event(r) for r in rows])
    assert [e["text"] for e in timeline.events()] == [
        "strategy CHARGE (user)",
        "strategy IDLE (user)",
    ]
    assert timeline.take_fresh() == []
    # the dropped oldest can come again (a re-read): it is new to a bounded timeline
    assert timeline.add(strategy_event(rows[1]))

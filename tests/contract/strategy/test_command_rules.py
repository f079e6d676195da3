"""The strategy decision table (services.strategy.commands.decide), without I/O."""

from __future__ import annotations

import pytest

from services.strategy.commands import Outcome, RobotState, decide

CODES = frozenset({"GOTO_AVOID", "GOTO_DIRECT", "CHARGE", "IDLE"})


def state(code: str | None = "GOTO_AVOID", resume: str | None = None) -> RobotState:
    return RobotState(True, code, resume)


@pytest.mark.parametrize(
    ("command", "argument", "before", "expected"),
    [
        (
            "SET_STRATEGY",
            "GOTO_DIRECT",
            state(),
            Outcome(True, "GOTO_AVOID -> GOTO_DIRECT", "GOTO_DIRECT"),
        ),
        ("set_strategy", " idle ", state(), Outcome(True, "GOTO_AVOID -> IDLE", "IDLE")),
        # a person's explicit choice drops the strategy CMD_RESUME would go back to
        (
            "SET_STRATEGY",
            "IDLE",
            state("CHARGE", "GOTO_AVOID"),
            Outcome(True, "CHARGE -> IDLE", "IDLE"),
        ),
        (
            "CMD_BATTSAVE",
            None,
            state("GOTO_DIRECT"),
            Outcome(True, "GOTO_DIRECT -> CHARGE (resume GOTO_DIRECT)", "CHARGE", "GOTO_DIRECT"),
        ),
        (
            "CMD_RESUME",
            None,
            state("CHARGE", "GOTO_DIRECT"),
            Outcome(True, "CHARGE -> GOTO_DIRECT (resumed)", "GOTO_DIRECT"),
        ),
    ],
)
def test_accepted(
    command: str, argument: str | None, before: RobotState, expected: Outcome
) -> None:
    assert decide(command, argument, before, CODES) == expected


@pytest.mark.parametrize(
    ("command", "argument", "before", "why"),
    [
        ("CANCEL", None, state(), "unknown command"),
        ("SET_STRATEGY", "NOPE", state(), "unknown strategy 'NOPE'"),
        ("SET_STRATEGY", "", state(), "needs a strategy code"),
        ("CMD_BATTSAVE", None, state("CHARGE", "GOTO_AVOID"), "already in CHARGE"),
        ("CMD_RESUME", None, state(), "nothing to resume"),
        ("SET_STRATEGY", "IDLE", RobotState(False, None, None), "unknown robot"),
    ],
)
def test_rejected(command: str, argument: str | None, before: RobotState, why: str) -> None:
    outcome = decide(command, argument, before, CODES)
    assert not outcome.accepted and outcome.strategy_code is None
    assert why in outcome.reason


def test_battsave_needs_a_charge_strategy() -> None:
    outcome = decide("CMD_BATTSAVE", None, state(), CODES - {"CHARGE"})
    assert not outcome.accepted and "no CHARGE strategy" in outcome.reason

"""What a strategy command does: a pure function of the command and the robot's state.

Kept free of I/O so the rules that apply it stay short and the decision table below is the
one place to read (CONTRACT.md, "Conventions the shipped scenarios follow"):

==============  ===============================================  ============================
command         accepted when                                    effect
==============  ===============================================  ============================
SET_STRATEGY    the argument names a row of the strategy table   switch to it; resume_code
                                                                 cleared (a person's explicit
                                                                 choice supersedes it)
CMD_BATTSAVE    CHARGE exists and the robot is not in CHARGE     resume_code = current,
                                                                 switch to CHARGE
CMD_RESUME      resume_code is set                               switch to resume_code,
                                                                 clear it
anything else   never                                            rejected, nothing changes
==============  ===============================================  ============================

A command that would switch the robot to a strategy that cannot run now (it names a scenario
no live planner or controller offers: runnable.py) is rejected with that reason instead, and
nothing changes.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import Final

SET_STRATEGY: Final = "SET_STRATEGY"
CMD_BATTSAVE: Final = "CMD_BATTSAVE"
CMD_RESUME: Final = "CMD_RESUME"
COMMANDS: Final = (SET_STRATEGY, CMD_BATTSAVE, CMD_RESUME)

# The strategy CMD_BATTSAVE switches to, and the one a robot gets when it has none.
CHARGE: Final = "CHARGE"
DEFAULT_STRATEGY: Final = "GOTO_AVOID"


@dataclass(frozen=True)
class RobotState:
    """The robot's active_strategy row as the rule read it (None: the robot has no row)."""

    known_robot: bool
    strategy_code: str | None
    resume_code: str | None


@dataclass(frozen=True)
class Outcome:
    """Accepted with the new (strategy_code, resume_code), or rejected; always a reason."""

    accepted: bool
    reason: str
    strategy_code: str | None = None
    resume_code: str | None = None

    @classmethod
    def reject(cls, reason: str) -> Outcome:
        return cls(False, reason)


def _can_run(_code: str) -> str | None:
    return None


def decide(
    command: str,
    argument: str | None,
    state: RobotState,
    strategies: Collection[str],
    refusal: Callable[[str], str | None] = _can_run,
) -> Outcome:
    """Apply ``command`` to ``state`` given the strategy codes that exist now; ``refusal``
    says why a strategy cannot run now (None: it can), and a switch to it is rejected."""
    outcome = _decide(command, argument, state, strategies)
    if outcome.accepted and outcome.strategy_code is not None:
        why = refusal(outcome.strategy_code)
        if why is not None:
            return Outcome.reject(why)
    return outcome


def _decide(
    command: str, argument: str | None, state: RobotState, strategies: Collection[str]
) -> Outcome:
    name = command.strip().upper()
    if not state.known_robot:
        return Outcome.reject("unknown robot")
    current = state.strategy_code
    if current is None:
        # The meta rule gives every robot its default before applying commands; this only
        # happens if a person deleted the row in between.
        return Outcome.reject("robot has no active strategy yet")

    if name == SET_STRATEGY:
        code = (argument or "").strip().upper()
        if not code:
            return Outcome.reject("SET_STRATEGY needs a strategy code as its argument")
        if code not in strategies:
            known = ", ".join(sorted(strategies))
            return Outcome.reject(f"unknown strategy {code!r} (known: {known})")
        return Outcome(True, f"{current} -> {code}", code, None)

    if name == CMD_BATTSAVE:
        if current == CHARGE:
            return Outcome.reject(f"already in {CHARGE}")
        if CHARGE not in strategies:
            return Outcome.reject(f"no {CHARGE} strategy in the strategy table")
        return Outcome(True, f"{current} -> {CHARGE} (resume {current})", CHARGE, current)

    if name == CMD_RESUME:
        resume = state.resume_code
        if resume is None:
            return Outcome.reject("nothing to resume (no resume_code)")
        if resume not in strategies:
            return Outcome.reject(f"resume strategy {resume!r} no longer exists")
        return Outcome(True, f"{current} -> {resume} (resumed)", resume, None)

    expected = ", ".join(COMMANDS)
    return Outcome.reject(f"unknown command {command!r} (expected one of {expected})")

"""Choosing among recommendations: pure functions, no I/O.

The decision service knows no scenario by name: it compares ``priority`` among the live
(unexpired) recommendations of one robot and one kind; ties go to the newest row (highest
id). A new scenario family is obeyed the moment it writes a row with a priority. A live row
is the contract's :class:`~common.contract.recommendations.Recommendation` (with its ``id``
and ``treated_by``), as every writer wrote it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Final

from common.contract import tables
from common.contract.inserts import Insert
from common.contract.recommendations import Recommendation

# Re-issue the current winner at least this often (sim s), so the bridge's 0.5 s watchdog
# never stops a robot that has a live recommendation.
REISSUE_PERIOD_S: Final = 0.1
# Tolerance on the cadence test: sim stamps are floats that were added up.
_EPS: Final = 1e-9

NO_LIVE_RECOMMENDATION: Final = "no live recommendation"

# command2robot's INSERT, arguments and image, from its declaration: RobotDecision's fields
# are the columns' names
COMMAND2ROBOT: Final = Insert(tables.COMMAND2ROBOT)


@dataclass(frozen=True)
class Issued:
    """The newest command2robot row of a robot, as the service last wrote (or read) it."""

    id: int
    stamp: float
    linear_mps: float
    angular_rps: float
    recommendation_id: int | None
    source: str | None


@dataclass(frozen=True)
class RobotDecision:
    """A command2robot row to write."""

    robot_id: str
    stamp: float
    linear_mps: float
    angular_rps: float
    recommendation_id: int | None
    source: str | None
    considered_ids: tuple[int, ...]
    reason: str

    def image(self) -> dict[str, Any]:
        """The command2robot row's image: its columns as written (CONTRACT.md "Row images"),
        as its declaration lists them (its fields are the columns' names)."""
        return COMMAND2ROBOT.image(self)


@dataclass(frozen=True)
class SystemDecision:
    """A system_command row to write."""

    robot_id: str
    stamp: float
    command: str
    recommendation_id: int
    considered_ids: tuple[int, ...]
    reason: str

    def image(self) -> dict[str, Any]:
        """The system_command row's image: its columns as written, ``pending``."""
        return {
            "robot_id": self.robot_id,
            "command": self.command,
            "recommendation_id": self.recommendation_id,
            "considered_ids": list(self.considered_ids),
            "reason": self.reason,
            "status": "pending",
            "stamp": self.stamp,
        }


def winner(recommendations: Sequence[Recommendation]) -> Recommendation:
    """Highest priority; ties go to the newest (highest id)."""
    return max(recommendations, key=lambda r: (r.priority, r.id))


def explain(win: Recommendation, considered: Sequence[Recommendation]) -> str:
    """``safety_stop (priority 100) over avoid_left (50), turn_then_move (10): <its reason>``.

    Each other source is named once, with its best live row: a 30 Hz planner has a dozen
    live rows and the reason is for people.
    """
    best: dict[str, Recommendation] = {}
    for rec in considered:
        if rec.source == win.source:
            continue
        held = best.get(rec.source)
        if held is None or (rec.priority, rec.id) > (held.priority, held.id):
            best[rec.source] = rec
    losers = sorted(best.values(), key=lambda r: (-r.priority, -r.id))
    text = f"{win.source} (priority {win.priority})"
    if losers:
        text += " over " + ", ".join(f"{r.source} ({r.priority})" for r in losers)
    else:
        text += " unopposed"
    if win.reason:
        text += f": {win.reason}"
    return text


def reissue_due(last: Issued | None, now: float) -> bool:
    """Whether :func:`decide_robot` would re-issue ``last``'s winner unchanged at ``now``:
    REISSUE_PERIOD_S of sim time passed since it (or sim time went back). True with none."""
    return last is None or not (last.stamp <= now < last.stamp + REISSUE_PERIOD_S - _EPS)


def decide_robot(
    robot_id: str,
    live: Sequence[Recommendation],
    last: Issued | None,
    now: float,
) -> RobotDecision | None:
    """The command2robot row to write now for ``robot_id``, or None if none is due.

    A row is due when the winner or its values changed, when REISSUE_PERIOD_S of sim time
    passed since the last one (or sim time went back: the sim restarted), and, with nothing
    live, once: a stop, if the last row was not one already.
    """
    if not live:
        if last is None or last.recommendation_id is None:
            return None
        return RobotDecision(robot_id, now, 0.0, 0.0, None, None, (), NO_LIVE_RECOMMENDATION)
    win = winner(live)
    linear = float(win.linear_mps or 0.0)
    angular = float(win.angular_rps or 0.0)
    if last is not None and (
        last.recommendation_id == win.id
        and last.linear_mps == linear
        and last.angular_rps == angular
        and last.stamp <= now < last.stamp + REISSUE_PERIOD_S - _EPS
    ):
        return None
    considered = tuple(sorted(r.id for r in live))
    return RobotDecision(
        robot_id, now, linear, angular, win.id, win.source, considered, explain(win, live)
    )


def decide_system(
    robot_id: str, live: Sequence[Recommendation], now: float
) -> SystemDecision | None:
    """A system_command row for a new winning system recommendation, else None.

    A winner that a decision already treated is not sent again: one system_command per
    winning recommendation. A treated winner still hides lower ones while it is live.
    """
    if not live:
        return None
    win = winner(live)
    if win.treated_by is not None or win.system_command is None:
        return None
    considered = tuple(sorted(r.id for r in live))
    return SystemDecision(robot_id, now, win.system_command, win.id, considered, explain(win, live))

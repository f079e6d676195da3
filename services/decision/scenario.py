"""The decision scenario's target rules: write what the meta-decision rule decided.

- :class:`IssueRobotCommand`: the velocity commands decided in one activation, already made
  (one per robot, every robot it decided for in that activation); this rule only writes
  them: one command2robot row per robot and ``treated_by`` of the rows each considered, all
  in ONE statement and one commit (batching across robots: at 10 robots a command's cost is
  mostly its commit), then one notification per robot, with its row's image, so the bridge
  sends each at once.
- :class:`IssueSystemCommand`: one decided system command (the feedback loop to the
  strategy), for a new winning system recommendation: the pending system_command row and
  ``treated_by`` of the system recommendations considered, in one statement, then a
  notification of system_command so the strategy service applies it at once.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

from common import log
from common.engine import Rule
from services.decision.arbitration import RobotDecision, SystemDecision
from services.decision.view import DecisionView

logger = logging.getLogger("pnav.decision")


class IssueRobotCommand(Rule):
    scenario = "decision"

    def __init__(self, store: DecisionView, decisions: Sequence[RobotDecision]) -> None:
        self.store = store
        self.decisions = tuple(decisions)
        robots = {d.robot_id for d in self.decisions}
        # a wake or hurry for its one robot runs it; a batch of several robots' commands is
        # no one robot's and runs in whichever activation comes next
        self.robot_id = next(iter(robots)) if len(robots) == 1 else None

    async def actions(self) -> None:
        store = self.store
        # Decided in the last activation, written in this one: a robot given back to the
        # lease in between is its next owner's to decide now, and writing it here would
        # decide it twice (the hand-over waits for the activation under way, not for one
        # still to come: docs/REPLICAS.md).
        decisions = [d for d in self.decisions if store.owns(d.robot_id)]
        if not decisions:
            return
        previous = [store.issued(d.robot_id) for d in decisions]
        ids = await store.write_robot_commands(decisions)  # remembered as issued
        for d, before, row_id in zip(decisions, previous, ids, strict=True):
            if row_id is None:
                continue  # refused by the database: the source logged why
            # A re-issue of the same winner happens 10 times a sim second: only a change of
            # source (or a stop) is worth a line at INFO.
            changed = before is None or before.source != d.source
            level = logging.INFO if changed else logging.DEBUG
            if not logger.isEnabledFor(level):
                continue
            log.event(
                logger,
                level,
                "command2robot",
                robot=d.robot_id,
                id=row_id,
                stamp=round(d.stamp, 3),
                source=d.source,
                linear=d.linear_mps,
                angular=d.angular_rps,
                recommendation_id=d.recommendation_id,
                considered=len(d.considered_ids),
                reason=d.reason,
            )


class IssueSystemCommand(Rule):
    scenario = "decision"

    def __init__(self, store: DecisionView, decision: SystemDecision) -> None:
        self.store = store
        self.decision = decision
        self.robot_id = decision.robot_id  # a wake or hurry for this robot runs it

    async def actions(self) -> None:
        d = self.decision
        if not self.store.owns(d.robot_id):
            return  # given back since the decision: the next owner decides (as above)
        row_id = await self.store.write_system_command(d)
        log.event(
            logger,
            logging.INFO,
            "system_command",
            robot=d.robot_id,
            id=row_id,
            command=d.command,
            stamp=round(d.stamp, 3),
            recommendation_id=d.recommendation_id,
            considered=list(d.considered_ids),
            reason=d.reason,
        )

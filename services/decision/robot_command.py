"""Target rule: write one decided velocity command to command2robot.

Created by the meta-decision rule with the decision already made; this rule only writes it
(the command2robot row and ``treated_by`` of the rows considered, in one statement), then
notifies command2robot so the bridge sends it at once.
"""

from __future__ import annotations

import logging

from common import log
from common.engine import Rule
from services.decision.arbitration import RobotDecision
from services.decision.view import DecisionView

logger = logging.getLogger("pnav.decision")


class IssueRobotCommand(Rule):
    scenario = "decision"

    def __init__(self, store: DecisionView, decision: RobotDecision) -> None:
        self.store = store
        self.decision = decision
        self.robot_id = decision.robot_id  # a wake or hurry for this robot runs it

    async def actions(self) -> None:
        d = self.decision
        previous = self.store.issued(d.robot_id)
        row_id = await self.store.write_robot_command(d)  # the store remembers it as issued
        # A re-issue of the same winner happens 10 times a sim second: only a change of
        # source (or a stop) is worth a line at INFO.
        changed = previous is None or previous.source != d.source
        log.event(
            logger,
            logging.INFO if changed else logging.DEBUG,
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

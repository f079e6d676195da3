"""Target rule: write one decided system command (the feedback loop to the strategy).

Created by the meta-decision rule for a new winning system recommendation; writes the
pending system_command row and ``treated_by`` of the system recommendations considered, in
one statement, then notifies system_command so the strategy service applies it at once.
"""

from __future__ import annotations

import logging

from common import log
from common.engine import Rule
from services.decision.arbitration import SystemDecision
from services.decision.view import DecisionView

logger = logging.getLogger("pnav.decision")


class IssueSystemCommand(Rule):
    scenario = "decision"

    def __init__(self, store: DecisionView, decision: SystemDecision) -> None:
        self.store = store
        self.decision = decision
        self.robot_id = decision.robot_id  # a wake or hurry for this robot runs it

    async def actions(self) -> None:
        d = self.decision
        if not self.store.owns(d.robot_id):
            return  # given back since the decision: the next owner decides (robot_command.py)
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

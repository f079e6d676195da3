"""Target rule: write one decided velocity command to command2robot.

Created by the meta-decision rule with the decision already made; this rule only writes it
(the command2robot row and ``treated_by`` of the rows considered, in one statement), then
notifies command2robot so the bridge sends it at once.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import services.decision.store as store
from common import log
from common.engine import Rule
from services.decision.arbitration import Issued, RobotDecision

if TYPE_CHECKING:
    from services.decision.service import DecisionService

logger = logging.getLogger("pnav.decision")


class IssueRobotCommand(Rule):
    scenario = "decision"

    def __init__(self, service: DecisionService, decision: RobotDecision) -> None:
        self.service = service
        self.decision = decision

    async def actions(self) -> None:
        d = self.decision
        row_id = await store.write_robot_command(self.service.runtime.database, d)
        previous = self.service.issued.get(d.robot_id)
        self.service.issued[d.robot_id] = Issued(
            row_id, d.stamp, d.linear_mps, d.angular_rps, d.recommendation_id, d.source
        )
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

"""The decision service: live recommendations -> command2robot and system_command.

One Proactive Engine seeded with the meta-decision rule; see docs/DECISION.md. It keeps the
last command it issued per robot in memory, bootstrapped from command2robot at start, so a
restarted process carries on.
"""

from __future__ import annotations

import sys

from common.runtime import Runtime
from common.service import ScenarioService
from services.decision.arbitration import Issued
from services.decision.meta import MetaDecision


class DecisionService(ScenarioService):
    service = "decision"

    def __init__(self, runtime: Runtime) -> None:
        super().__init__(runtime)
        # Robot id -> newest command2robot row; read from the table on the first look.
        self.issued: dict[str, Issued] = {}
        self.bootstrapped = False
        self.waiting_logged = False
        # Robots taken over from another replica: their issued entry is read again.
        self.regained: set[str] = set()

    def seed(self) -> None:
        self.engine.add_meta(lambda: MetaDecision(self))

    def on_ownership_change(self, gained: frozenset[str], lost: frozenset[str]) -> None:
        for robot_id in lost:
            self.issued.pop(robot_id, None)
        self.regained -= lost
        self.regained |= gained
        super().on_ownership_change(gained, lost)


def main() -> int:
    return DecisionService.main()


if __name__ == "__main__":
    sys.exit(main())

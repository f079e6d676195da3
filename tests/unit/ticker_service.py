"""A minimal scenario service, run as its own process by test_service_process.py."""

from __future__ import annotations

import sys

from common.engine import Rule
from common.service import ScenarioService


class Tick(Rule):
    scenario = "tick"
    meta = True
    watches = ("goal",)

    def rule_generation(self) -> list[Rule]:
        return [self.clone()]


class TickerService(ScenarioService):
    service = "ticker"

    def seed(self) -> None:
        self.engine.add_meta(Tick)


if __name__ == "__main__":
    sys.exit(TickerService.main())

"""The strategy service: sets each robot's active_strategy from user and system commands.

One Proactive Engine seeded with the meta-strategy rule; see docs/STRATEGY.md. All its state
is in the contract tables (active_strategy, the command rows' status), so a restarted
process carries on where the last one stopped.
"""

from __future__ import annotations

import sys

from common.runtime import Runtime
from common.service import ScenarioService
from services.strategy.meta import MetaStrategy


class StrategyService(ScenarioService):
    service = "strategy"

    def __init__(self, runtime: Runtime) -> None:
        super().__init__(runtime)
        # Robots already warned about a missing default strategy (log once, not every F).
        self.warned: set[str] = set()

    def seed(self) -> None:
        self.engine.add_meta(lambda: MetaStrategy(self))

    def sim_stamp(self) -> float | None:
        """Sim time now, or None before the sim's clock was ever heard (stamp stays NULL)."""
        clock = self.runtime.clock
        return clock.now() if clock.started else None


def main() -> int:
    return StrategyService.main()


if __name__ == "__main__":
    sys.exit(main())

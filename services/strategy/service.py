"""The strategy service: sets each robot's active_strategy from user and system commands.

Wiring only (docs/STRATEGY.md): a :class:`~services.strategy.store.StrategyStore` on
Postgres and the sim clock, the meta-strategy rule seeded on the engine. All its state is
in the contract tables (active_strategy, the command rows' status), so a restarted process
carries on where the last one stopped.
"""

from __future__ import annotations

import sys

import services.strategy.meta as meta
from common.bus import Notification
from common.runtime import Runtime
from common.service import ScenarioService
from services.strategy.source import PgStrategySource
from services.strategy.store import StrategyStore


class StrategyService(ScenarioService):
    service = "strategy"

    def __init__(self, runtime: Runtime) -> None:
        super().__init__(runtime)
        clock = runtime.clock
        self.store = StrategyStore(
            PgStrategySource(runtime.database), clock.now_if_started, self.owns
        )

    def seed(self) -> None:
        meta.seed(self.engine, self.store)

    def on_notification(self, note: Notification) -> None:
        self.store.note(note)


def main() -> int:
    return StrategyService.main()


if __name__ == "__main__":
    sys.exit(main())

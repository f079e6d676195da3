"""The decision service: live recommendations -> command2robot and system_command.

Wiring only (docs/DECISION.md): a :class:`~services.decision.store.DecisionStore` on
Postgres and the sim clock, the meta-decision rule seeded on the engine, and ownership
changes (replicas) forwarded to the store, which keeps the last command issued per robot
(read from command2robot at start, so a restarted process carries on).
"""

from __future__ import annotations

import sys
import time

import services.decision.meta as meta
from common.bus import Notification
from common.runtime import Runtime
from common.service import ScenarioService
from services.decision.store import DecisionStore, PgDecisionSource


class DecisionService(ScenarioService):
    service = "decision"

    def __init__(self, runtime: Runtime) -> None:
        super().__init__(runtime)
        clock = runtime.clock
        # the store's period fallback counts sim time in lockstep (a run that does not depend
        # on the machine's speed), wall time otherwise (sim time may stand still)
        period_clock = clock.now if runtime.ledger is not None else time.monotonic
        self.store = DecisionStore(
            PgDecisionSource(runtime.database),
            clock.now_if_started,
            self.owns,
            clock=period_clock,
        )

    def notifications_lost(self) -> int | None:
        return self.store.notifications_lost

    def images_refused(self) -> dict[str, int] | None:
        return self.store.images_refused

    def seed(self) -> None:
        meta.seed(self.engine, self.store)

    def on_notification(self, note: Notification) -> None:
        self.store.note(note)

    def on_ownership_change(self, gained: frozenset[str], lost: frozenset[str]) -> None:
        self.store.on_ownership_change(gained, lost)
        super().on_ownership_change(gained, lost)


def main() -> int:
    return DecisionService.main()


if __name__ == "__main__":
    sys.exit(main())

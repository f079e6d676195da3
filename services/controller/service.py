"""The controller service: ``python -m services.controller``.

Wiring only: one Proactive Engine seeded with the meta-controller (meta.py), which runs the
controller scenarios each robot's strategy names (every scenario the installed packages name
under the ``pnav.controller.scenarios`` entry points, found at start), against the store
(store.py), which the notifications and the robot leases keep informed.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Collection

from common import log
from common.bus import Notification
from common.controller_core.scenario import installed_scenarios
from common.runtime import Runtime
from common.service import ScenarioService
from services.controller.meta import seed_controller
from services.controller.source import PgControllerSource
from services.controller.store import ControllerStore

logger = logging.getLogger("pnav.controller")


class ControllerService(ScenarioService):
    service = "controller"
    listens = ControllerStore.listens  # none by default: why in store.py

    def __init__(self, runtime: Runtime) -> None:
        super().__init__(runtime)
        sim = runtime.clock

        def sim_now() -> float | None:
            return sim.now() if sim.started else None

        # in lockstep the caches count sim time, so a run does not depend on the machine
        clock = sim.now if runtime.ledger is not None else time.monotonic
        source = PgControllerSource(runtime.database)
        self.store = ControllerStore(source, clock, sim_now, serves=self.owns)
        # one INSERT per activation for every recommendation its rules made
        self.engine.at_activation_end(self.store.defer_recommendations())
        self.scenarios: tuple[str, ...] | None = None  # found at seed

    def notifications_lost(self) -> int | None:
        return self.store.notifications_lost

    def images_refused(self) -> dict[str, int] | None:
        return self.store.images_refused

    def seed(self) -> None:
        scenarios = installed_scenarios()
        log.event(logger, logging.INFO, "controller scenarios", names=",".join(sorted(scenarios)))
        seed_controller(self.engine, self.store, scenarios, owns=self.owns)
        self.scenarios = tuple(scenarios)

    def offered_scenarios(self) -> Collection[str] | None:
        # what a strategy's controller_scenarios may name (scenario_offer)
        return self.scenarios

    def on_notification(self, note: Notification) -> None:
        self.store.note(note)

    def on_ownership_change(self, gained: frozenset[str], lost: frozenset[str]) -> None:
        # The meta-controller ends a lost robot's scenarios in its next run (it only wants
        # owned robots); what was read and recommended for a robot that changed hands is
        # forgotten (another replica served it meanwhile).
        self.store.forget(gained | lost)
        super().on_ownership_change(gained, lost)

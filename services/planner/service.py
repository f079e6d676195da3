"""The planner service: its own Proactive Engine, seeded with the meta-planner.

``python -m services.planner``. The planner is the only service that knows the goal: it
reads robots, maps, charging stations, goals, strategies, odometry and the battery, and
writes velocity recommendations (turn_then_move, move_while_turning, and any move scenario
a package registers under ``pnav.planner.scenarios``), system recommendations
(battery_check, charge_complete) and goal status. See docs/PLANNER.md.
"""

from __future__ import annotations

import time
from collections.abc import Collection

import services.planner.meta as meta
from common.bus import Notification
from common.contract import keys
from common.runtime import Runtime
from common.service import ScenarioService
from services.planner.meta import PlannerRules
from services.planner.source import PgPlannerSource
from services.planner.store import PlannerStore


class PlannerService(ScenarioService):
    service = "planner"
    # the controllers' offers: a strategy naming one none offers fails its goals (meta.py)
    listens = frozenset({keys.SCENARIO_OFFER})

    def __init__(self, runtime: Runtime) -> None:
        super().__init__(runtime)
        clock = runtime.clock
        # in lockstep the planner's own gates (replan, retry, refresh) count sim time too,
        # as the engine's F does: what it does then depends on the sim alone
        gates = clock.now if runtime.ledger is not None else time.monotonic
        self.store = PlannerStore(
            PgPlannerSource(runtime.database), gates, clock.now, lambda: clock.started
        )
        # one INSERT per activation for every velocity recommendation its rules made
        self.engine.at_activation_end(self.store.defer_recommendations())
        self.rules: PlannerRules | None = None

    def notifications_lost(self) -> int | None:
        return self.store.notifications_lost

    def images_refused(self) -> dict[str, int] | None:
        return self.store.images_refused

    def seed(self) -> None:
        # the move scenarios installed now: a new one needs a restart, no edit here
        self.rules = meta.seed(self.engine, self.store, meta.move_scenarios(), owns=self.owns)

    def offered_scenarios(self) -> Collection[str] | None:
        # the move scenarios a strategy's planner_scenario may name (scenario_offer)
        return None if self.rules is None else tuple(self.rules.scenarios)

    def on_ownership_change(self, gained: frozenset[str], lost: frozenset[str]) -> None:
        # A robot given up or taken over starts from a blank state (route, charger, poses,
        # obstacles seen, goal read) and its rules end: the next meta run starts those of
        # the robots this replica owns, which rebuild it from the tables.
        self.store.forget(gained | lost)
        if self.rules is not None:
            self.rules.forget(gained | lost)
        super().on_ownership_change(gained, lost)

    def on_notification(self, note: Notification) -> None:
        self.store.note(note)

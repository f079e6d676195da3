"""The planner service: its own Proactive Engine, seeded with the meta-planner.

``python -m services.planner``. The planner is the only service that knows the goal: it
reads robots, maps, charging stations, goals, strategies, odometry and the battery, and
writes velocity recommendations (turn_then_move, move_while_turning), system
recommendations (battery_check, charge_complete) and goal status. See docs/PLANNER.md.
"""

from __future__ import annotations

import time

from common.bus import Notification
from common.contract import keys
from common.runtime import Runtime
from common.service import ScenarioService
from services.planner.meta import MetaPlanner
from services.planner.state import PlannerState


class PlannerService(ScenarioService):
    service = "planner"

    def __init__(self, runtime: Runtime) -> None:
        super().__init__(runtime)
        clock = runtime.clock
        # in lockstep the planner's own gates (replan, retry, refresh) count sim time too,
        # as the engine's F does: what it does then depends on the sim alone
        wall = clock.now if runtime.ledger is not None else time.monotonic
        self.state = PlannerState(runtime.database, clock.now, lambda: clock.started, wall=wall)

    def seed(self) -> None:
        self.engine.add_meta(lambda: MetaPlanner(self.state, owns=self.owns))

    def on_ownership_change(self, gained: frozenset[str], lost: frozenset[str]) -> None:
        # A robot given up or taken over starts from a blank state (route, charger, poses,
        # obstacles seen, goal read): the rules rebuild it from the tables. No slots either,
        # so a lost robot's target rules end themselves at their next run.
        self.state.forget(gained | lost)
        super().on_ownership_change(gained, lost)

    def on_notification(self, note: Notification) -> None:
        # flags robot, map and charger changes, so the meta-planner re-reads those tables
        # only when they change
        self.state.note(keys.notify_key(note.table, note.robot), b"")

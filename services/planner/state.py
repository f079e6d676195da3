"""Transitional: the names pnav/monolith/stack.py and pnav/monolith/sql.py import today.

The planner's state now lives in store.py (the contract), world.py, obstacles.py,
routes.py and chargers.py; the monolith's own in-memory source and builder are in
pnav/monolith/planner.py. Delete this module once stack.py and sql.py use those.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from common.bus import Notification
from common.db import Database
from services.planner.routes import Target
from services.planner.store import LIVE_SYSTEM_SQL as _LIVE_SYSTEM
from services.planner.store import MARK_REACHED_SQL as _MARK_REACHED
from services.planner.store import PgPlannerSource, PlannerStore
from services.planner.world import MapData, RobotInfo, RobotState, Station

__all__ = [
    "_LIVE_SYSTEM",
    "_MARK_REACHED",
    "MapData",
    "PlannerState",
    "RobotInfo",
    "RobotState",
    "Station",
    "Target",
]


class PlannerState(PlannerStore):
    """The store on SQL, built as the monolith built the old state (``wall``: its clock)."""

    def __init__(
        self,
        db: Database,
        now: Callable[[], float],
        started: Callable[[], bool],
        wall: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__(PgPlannerSource(db), wall, now, started)

    def note(self, note: Notification | str, payload: bytes = b"") -> None:
        """Also the old observer's ``note(key, payload)``."""
        super().note(note if isinstance(note, Notification) else Notification.decode(note, payload))

"""The services' Proactive Engines, stepped by the monolith's loop on sim time.

Each service keeps its own :class:`~common.engine.Engine` (two queues, N, F) with its own meta
rules, seeded by the service's own seeding code; what changes is who starts an activation:

- in the stack, ``Engine.run`` starts one when its trigger says so: a Zenoh notification for
  a watched table (``wake``), a rule's ``hurry``, or F (50 ms wall) after the previous start;
- here the monolith's loop asks :meth:`SteppedEngine.due` after every physics step (the same
  three reasons, read from the engine's own ``signals``, with F counted in *sim* seconds from
  the last full activation) and awaits :meth:`SteppedEngine.activate` while one is due,
  focused on the robots the wakes named exactly as ``Engine.run`` does (``Engine.focus``).

Activations run on a real event loop (the monolith's), so a rule's async steps await the
in-memory stores exactly as they await Postgres in the stack.
"""

from __future__ import annotations

from collections.abc import Callable

from common.config import EngineSettings
from common.engine import Engine
from pnav.monolith.contract import AdapterError


class SteppedEngine(Engine):
    """An Engine whose activations the monolith's loop starts, on sim time."""

    def __init__(self, name: str, now: Callable[[], float]) -> None:
        # F, N and P as the services read them (PNAV_ENGINE_*; defaults 50 ms, 1000, 0).
        # F also bounds one activation; sim time stands still while one runs, so it never
        # cuts one short (in the stack F is wall time: a slow rule can leave work for later)
        # A failure of the monolith's own plumbing (AdapterError) must stop the run, not be
        # discarded like a rule's error.
        super().__init__(EngineSettings.from_env(), name=name, clock=now, fatal=(AdapterError,))
        self.signals.woken = True  # a service's first activation starts at once

    def due(self, now: float) -> bool:
        """A notification came, a rule hurried, or F has passed since the last full start."""
        last = self.full_started
        return self.signals.pending or last is None or now >= last + self.settings.period_s

    async def activate(self, now: float) -> int:
        """One activation at sim time ``now`` (the engine's clock); how many rules ran."""
        self.signals.take()
        return await self.activation(self.focus())

    @property
    def errors(self) -> int:
        """Errors the engine counted: a rule's own failures, survived as in the stack."""
        return sum(s.errors for s in self.stats())

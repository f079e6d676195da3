"""Running the services' Proactive Engines in lockstep with the sim, in one thread.

Each service keeps its own :class:`~common.engine.Engine` (two queues, N, F) with its own
meta rules, exactly as its process seeds it; what changes is who starts an activation:

- in the stack, ``Engine.run`` starts one when a Zenoh notification for a watched table
  arrives, when a rule called ``hurry()``, or F (50 ms wall) after the previous start;
- here, :class:`LockstepEngine` records the same three triggers (``wake`` from the in-memory
  contract's change listener, ``hurry``, and F counted in *sim* seconds) and the monolith's
  loop calls :meth:`LockstepEngine.activate` while one is due.

The rules' async steps await only the in-memory contract, whose coroutines never suspend, so
:func:`run_sync` drives an activation to its end without an event loop.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

from common.config import EngineSettings
from common.engine import Engine, Rule
from common.engine.stats import RuleStats
from pnav.monolith.contract import AdapterError

T = TypeVar("T")


def run_sync(coro: Coroutine[Any, Any, T]) -> T:
    """The result of a coroutine that never suspends (everything it awaits is ready)."""
    try:
        coro.send(None)
    except StopIteration as done:
        result: T = done.value
        return result
    coro.close()
    raise AdapterError("an activation awaited something not ready: no event loop runs here")


class LockstepEngine(Engine):
    """An Engine whose activations the monolith's loop starts, on sim time."""

    def __init__(self, name: str, now: Callable[[], float]) -> None:
        # F, N and P as the services read them (PNAV_ENGINE_*; defaults 50 ms, 1000, 0)
        super().__init__(EngineSettings.from_env(), name=name)
        # F also bounds one activation; sim time stands still while one runs, so it never
        # cuts one short (in the stack F is wall time: a slow rule can leave work for later)
        self.clock = now
        self.woken = True  # a service's first activation starts at once
        self.hurried = False
        self.started_at = -math.inf
        self.errors = 0

    def wake(self) -> None:
        self.woken = True

    def hurry(self) -> None:
        self.hurried = True

    def due(self, now: float) -> bool:
        """A notification came, a rule hurried, or F has passed since the last start."""
        return self.woken or self.hurried or now >= self.started_at + self.settings.period_s

    def activate(self, now: float) -> int:
        """One activation at sim time ``now``; how many rules ran."""
        self.woken = self.hurried = False
        self.started_at = now
        ran = run_sync(self.activation())
        # A rule's own failure (a guard that raised, an error in its actions) is logged,
        # counted and survived as in the stack; the count tells a run it was not clean.
        self.errors = sum(s.errors for s in self.stats())
        return ran

    def _discard_on_error(self, rule: Rule, stats: RuleStats, step: str) -> None:
        # The engine calls this inside its ``except``: a failure of the monolith's own
        # plumbing (e.g. a statement the in-memory contract does not know) must stop the
        # run, not be discarded like a rule's error; a rule's own error is handled as in the
        # stack (logged, rule discarded, meta rule re-seeded).
        failure = sys.exc_info()[1]
        if isinstance(failure, AdapterError):
            raise failure
        super()._discard_on_error(rule, stats, step)

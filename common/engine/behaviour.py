"""A long-lived rule, the engine's own kind: one object per running target scenario.

A one-shot rule (:class:`~common.engine.Rule`) runs its five steps once and is discarded; a
rule that must live on returns a clone of itself. A *target scenario* that runs for as long as
a meta rule wants it (a controller scenario per (robot, scenario), a planner rule per (robot,
kind)) is a :class:`Behaviour` instead, with the lifecycle of py_trees' ``Behaviour``:

``initialise()``      once, when the supervisor starts the rule for its key (before it is
                      first queued)
``update``            steps 1 to 4 (data acquisition, activation guards, conditions,
                      actions), run by the engine in every activation on *the same object*:
                      what the scenario keeps between its runs (a tracker, the last path it
                      stopped for) lives in ``self``
``terminate(why)``    once, when it ends: its key is no longer wanted (the strategy changed,
                      the robot left or went to another replica), its rule was lost to an
                      error, or the service stops (:meth:`Engine.close`)

Step 5 is the engine's: the behaviour goes back into the queue while it runs
(:meth:`Behaviour.rule_generation` returns the object itself) and leaves it after it ended.
An ended behaviour still queued runs once more with ``live`` false, so its guards (which test
``live``) keep it from acting, and is then dropped: two scenarios never act for one key at
once, and the engine never needs to search its queues.

``key`` names what it runs for (say ``(robot_id, scenario)``), ``spec`` what it follows (the
robot's limits, the strategy and its params); a changed spec reaches a running behaviour
through :meth:`Behaviour.reconfigure` (the supervisor's choice, common.engine.supervisor).
"""

from __future__ import annotations

from collections.abc import Hashable
from typing import Generic, TypeVar

from common.engine.rule import Rule

K = TypeVar("K", bound=Hashable)
S = TypeVar("S")

ENDED = "no longer wanted"
LOST = "its rule was discarded after an error"
STOPPED = "the service stopped"


class Behaviour(Rule, Generic[K, S]):
    """A target rule that lives from :meth:`initialise` to :meth:`terminate`."""

    def __init__(self, key: K, spec: S) -> None:
        self.key = key
        self.spec = spec
        self.live = False  # between start() and stop(): it acts and stays queued
        self.lost = False  # the engine discarded it on an error (its supervisor restarts it)

    # -- the lifecycle, for subclasses -----------------------------------------------------
    def initialise(self) -> None:
        """The scenario starts: once, before the first run."""

    def reconfigure(self, spec: S) -> None:
        """The spec changed while it runs; the rule sees it from its next run."""
        self.spec = spec

    def terminate(self, why: str) -> None:
        """The scenario ended (``why``: no longer wanted, lost, the service stopped)."""

    def resume(self, lost: Behaviour[K, S]) -> None:
        """Started (initialised) again in place of ``lost``, which the engine discarded on an
        error: take from it what must outlive the error (the default takes nothing)."""

    # -- the supervisor's and the engine's side -------------------------------------------------
    def start(self) -> None:
        """Begin: :meth:`initialise`, then live (queued by whoever started it)."""
        self.initialise()
        self.live = True

    def stop(self, why: str) -> bool:
        """End now, once: not live any more, then :meth:`terminate`. Whether it was live."""
        if not self.live:
            return False
        self.live = False
        self.terminate(why)
        return True

    def rule_generation(self) -> list[Rule]:
        """Step 5: the behaviour itself while it lives (no clone), nothing once it ended."""
        return [self] if self.live else []

    def discarded(self, step: str) -> None:
        self.lost = True

    def __repr__(self) -> str:
        return f"<{self.name} key={self.key!r} live={self.live}>"

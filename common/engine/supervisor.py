"""Keeping target scenarios alive: the meta rule says what it wants, the supervisor does it.

A meta scenario (thesis section 3.3) creates the target rules of its scenarios and must make
sure each one runs exactly while it is wanted: one rule per (robot, scenario) in the
controller, one "move" and one "battery" rule per robot in the planner. Each is a
:class:`~common.engine.behaviour.Behaviour`, one object from start to end, and
:class:`Supervisor` does the bookkeeping for every service in the same way:

- the meta rule calls :meth:`Supervisor.reconcile` with what it wants now, a mapping from a
  key (say ``(robot_id, scenario)``) to a *spec* (whatever the target needs: the robot, the
  strategy, its params); it returns the behaviours to start, for the meta rule to hand to the
  engine in its rule generation;
- a key wanted and not running **starts**: a behaviour from the ``start(key, spec)``
  factory; its ``initialise()`` runs before it is queued;
- a key running and no longer wanted **ends**: ``terminate`` runs at once and the behaviour
  stops going back into the queue (a run of it still queued does nothing);
- a key whose spec changed is **reconfigured** in place (``reconfigure(spec)``), unless
  ``restart_on`` says the change needs a new rule (say the planner scenario itself changed),
  which ends the old behaviour and starts a new one in the same call, with no overlap;
- a key whose behaviour the engine **discarded** on an error (``lost``) is started again at
  the next reconcile: a new behaviour, which takes what must outlive the error from the lost
  one (``resume``).

Every hook runs on the meta rule's activation (inside ``reconcile``), never concurrently
with the behaviour's own steps.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Hashable, Iterable, Mapping
from typing import Generic, TypeVar

from common.engine.behaviour import ENDED, LOST, Behaviour
from common.engine.rule import Rule

K = TypeVar("K", bound=Hashable)
S = TypeVar("S")

log = logging.getLogger("pnav.supervisor")

Start = Callable[[K, S], Behaviour[K, S]]


class Supervisor(Generic[K, S]):
    """Starts, reconfigures, ends and restarts the behaviours a meta rule wants."""

    def __init__(
        self,
        name: str,
        start: Start[K, S],
        restart_on: Callable[[S, S], bool] | None = None,
    ) -> None:
        self.name = name
        self._start = start
        self._restart_on = restart_on
        self.running: dict[K, Behaviour[K, S]] = {}
        self.started = self.ended = self.restarted = 0

    def reconcile(self, wanted: Mapping[K, S]) -> list[Rule]:
        """Make what runs match ``wanted``; the behaviours to start (for rule generation)."""
        new: list[Rule] = []
        for key in [k for k in self.running if k not in wanted]:
            self.end(key, ENDED)
        for key, spec in wanted.items():
            rule = self.running.get(key)
            if rule is None:
                new.append(self._launch(key, spec, None))
            elif rule.lost:
                self.restarted += 1
                self.end(key, LOST)
                new.append(self._launch(key, spec, rule))
            elif rule.spec != spec:
                if self._restart_on is not None and self._restart_on(rule.spec, spec):
                    self.end(key, ENDED)
                    new.append(self._launch(key, spec, None))
                else:
                    rule.reconfigure(spec)
        return new

    def end(self, key: K, why: str = ENDED) -> None:
        """End ``key``'s behaviour now (it stops going back into the queue)."""
        rule = self.running.pop(key, None)
        if rule is None:
            return
        self.ended += 1
        try:
            rule.stop(why)
        except Exception:
            log.exception("terminate hook failed", extra={"supervisor": self.name})

    def end_all(self, keys: Iterable[K], why: str = ENDED) -> None:
        for key in list(keys):
            self.end(key, why)

    def rule(self, key: K) -> Behaviour[K, S] | None:
        """The behaviour running for ``key``, if any."""
        return self.running.get(key)

    def _launch(self, key: K, spec: S, lost: Behaviour[K, S] | None) -> Rule:
        rule = self._start(key, spec)
        rule.start()
        if lost is not None:
            rule.resume(lost)
        self.running[key] = rule
        self.started += 1
        return rule

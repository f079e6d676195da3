"""Keeping target scenarios alive: the meta rule says what it wants, the supervisor does it.

A meta scenario (thesis section 3.3) creates the target rules of its scenarios and must make
sure each one runs exactly while it is wanted: one rule per (robot, scenario) in the
controller, one "move" and one "battery" rule per robot in the planner. A target rule lives
by cloning itself, so "stopping" it means making it not clone itself, and a rule the engine
discarded on an error must be started again or the scenario silently ends (safety_stop with
it). :class:`Supervisor` does this bookkeeping for every service in the same way:

- the meta rule calls :meth:`Supervisor.reconcile` with what it wants now, a mapping from a
  key (say ``(robot_id, scenario)``) to a *spec* (whatever the target needs: the robot, the
  strategy, its params); it returns the rules to start, for the meta rule to hand to the
  engine in its rule generation;
- a key wanted and not running **starts**: a fresh :class:`Ticket` and a rule from the
  ``start`` factory; the rule's :meth:`Supervised.initialise` runs before it is queued;
- a key running and no longer wanted **ends**: its ticket goes dead, so its rule's next
  generation does not clone it; :meth:`Supervised.terminate` runs at once, on the newest
  instance of the rule;
- a key whose spec changed is **updated** in place: :meth:`Supervised.update` (by default it
  just takes the new spec), unless ``restart_on`` says the change needs a new rule (say the
  planner scenario itself changed), which ends the old rule and starts a new one in the same
  call, with no overlap: the old one stops cloning the moment its ticket dies;
- a key whose rule the engine **discarded** on an error (the engine calls
  :meth:`~common.engine.Rule.discarded`) is restarted at the next reconcile.

Lifecycle hooks of a supervised rule, like py_trees' ``initialise``/``update``/
``terminate``:

``initialise()``   the scenario starts (or restarts after a loss); once per ticket
``update(spec)``   the spec changed while it runs; the default stores it on the ticket
``terminate(why)`` the scenario ends: no longer wanted, or lost (``why`` says which)

Every hook runs on the meta rule's activation (inside ``reconcile``), never concurrently
with the rule's own steps.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Hashable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

from common.engine.rule import Rule

K = TypeVar("K", bound=Hashable)
S = TypeVar("S")

log = logging.getLogger("pnav.supervisor")

ENDED = "no longer wanted"
LOST = "its rule was discarded after an error"


@dataclass(eq=False)
class Ticket(Generic[K, S]):
    """One running scenario: what its rule and its clones share with the supervisor."""

    key: K
    spec: S
    live: bool = True  # False: the rule must not clone itself any more
    lost: bool = False  # the engine discarded the rule on an error
    rule: Supervised[K, S] | None = None  # the newest instance (for terminate)
    # What the scenario keeps between its runs (last scan used, last recommendation...);
    # handed to the next ticket of the same key when a lost rule is restarted.
    memory: dict[str, Any] = field(default_factory=dict)


class Supervised(Rule, Generic[K, S]):
    """A target rule run by a :class:`Supervisor`: it clones itself while its ticket lives.

    Subclasses implement the five steps as any rule does and read ``self.ticket.spec``;
    those that override :meth:`rule_generation` must return :meth:`keep_alive`'s result
    (plus any rules of their own).
    """

    def __init__(self, ticket: Ticket[K, S]) -> None:
        self.ticket = ticket

    @property
    def spec(self) -> S:
        return self.ticket.spec

    @property
    def live(self) -> bool:
        return self.ticket.live

    # -- lifecycle hooks -----------------------------------------------------------------------
    def initialise(self) -> None:
        """The scenario starts: called once per ticket, before the first run."""

    def update(self, spec: S) -> None:
        """The spec changed while the scenario runs; the rule sees it from its next run."""
        self.ticket.spec = spec

    def terminate(self, why: str) -> None:
        """The scenario ended (``why``: no longer wanted, or lost); clean up here."""

    # -- the engine's side ---------------------------------------------------------------------
    def keep_alive(self) -> list[Rule]:
        """The clone that keeps the scenario running, while its ticket lives."""
        if not self.ticket.live:
            return []
        twin = self.clone()
        self.ticket.rule = twin  # type: ignore[assignment]  # a clone is of the same class
        return [twin]

    def rule_generation(self) -> Iterable[Rule]:
        return self.keep_alive()

    def discarded(self, step: str) -> None:
        self.ticket.lost = True


Start = Callable[[Ticket[K, S]], Supervised[K, S]]


class Supervisor(Generic[K, S]):
    """Starts, updates, ends and restarts the target rules a meta rule wants."""

    def __init__(
        self,
        name: str,
        start: Start[K, S],
        restart_on: Callable[[S, S], bool] | None = None,
    ) -> None:
        self.name = name
        self._start = start
        self._restart_on = restart_on
        self.running: dict[K, Ticket[K, S]] = {}
        self.started = self.ended = self.restarted = 0

    def reconcile(self, wanted: Mapping[K, S]) -> list[Rule]:
        """Make what runs match ``wanted``; the rules to start (for rule generation)."""
        new: list[Rule] = []
        for key in [k for k in self.running if k not in wanted]:
            self.end(key, ENDED)
        for key, spec in wanted.items():
            ticket = self.running.get(key)
            if ticket is None:
                new.append(self._launch(key, spec, {}))
            elif ticket.lost:
                self.restarted += 1
                self.end(key, LOST)
                new.append(self._launch(key, spec, ticket.memory))
            elif ticket.spec != spec:
                if self._restart_on is not None and self._restart_on(ticket.spec, spec):
                    self.end(key, ENDED)
                    new.append(self._launch(key, spec, {}))
                elif ticket.rule is not None:
                    ticket.rule.update(spec)
                else:
                    ticket.spec = spec
        return new

    def end(self, key: K, why: str = ENDED) -> None:
        """End ``key``'s scenario now (its rule stops cloning itself)."""
        ticket = self.running.pop(key, None)
        if ticket is None:
            return
        ticket.live = False
        self.ended += 1
        if ticket.rule is not None:
            try:
                ticket.rule.terminate(why)
            except Exception:
                log.exception("terminate hook failed", extra={"supervisor": self.name})

    def end_all(self, keys: Iterable[K], why: str = ENDED) -> None:
        for key in list(keys):
            self.end(key, why)

    def ticket(self, key: K) -> Ticket[K, S] | None:
        return self.running.get(key)

    def _launch(self, key: K, spec: S, memory: dict[str, Any]) -> Rule:
        ticket: Ticket[K, S] = Ticket(key, spec, memory=memory)
        rule = self._start(ticket)
        ticket.rule = rule
        rule.initialise()
        self.running[key] = ticket
        self.started += 1
        return rule

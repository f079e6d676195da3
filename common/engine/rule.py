"""A rule of the Proactive Engine: one class, five steps, run once and then discarded.

The steps, run in this order by :class:`~common.engine.Engine` (thesis, figure 3.2):

1. ``data_acquisition()``  read what the rule needs into attributes. An exception here is
   logged with the rule's name, counted, and the rule is discarded (no rule generation).
2. ``activation_guards()`` AND-ed tests; the engine sets ``self.activated`` from them.
3. ``conditions()``        AND-ed tests, evaluated only if the guards held.
4. ``actions()``           run only if guards and conditions all held. An exception is
   logged, counted, and the rule discarded (no rule generation).
5. ``rule_generation()``   runs whether or not the rule was activated; the rules it returns
   go to the end of the engine's ``next`` queue. A continuous rule (a meta rule) returns a
   clone of itself here (``return [self.clone()]``); a long-lived target scenario is a
   :class:`~common.engine.behaviour.Behaviour` instead, one object from start to end.

A rule discarded on an error is told so (``discarded(step)``), so a supervisor that keeps
it alive can start it again (common.engine.supervisor).

Tests (steps 2 and 3) return a bool or an iterable of bools; a generator that ``yield``-s each
test stops at the first false one, like the thesis' "go to step 6". A result that is not a
bool, or a test that raises, is logged and counts as false: a broken guard makes the rule
inactive, it never crashes the engine.

``data_acquisition`` and ``actions`` may be plain or ``async def``; the engine awaits them
only when they are coroutines, so a trivial rule costs no event-loop round trip.

Class attributes:

- ``scenario``: the scenario the rule belongs to (statistics and logs group by it).
- ``meta``: True for a meta-scenario rule (a continuous rule that detects events and creates
  target-scenario rules). The engine re-seeds a meta rule lost to an error.
- ``watches``: contract tables whose change notifications should wake the engine. Only
  meta rules need to declare them; the service subscribes to every table they name.
- ``safety``: True for a rule that keeps robots safe (the controller's safety_stop): the
  engine runs the safety rules of an activation first and never cuts them by N or F
  (docs/ENGINE.md, "Safety rules first"); its work must be small and bounded.
"""

from __future__ import annotations

import copy
import inspect
from collections.abc import Iterable
from typing import Any, ClassVar, TypeAlias

Tests: TypeAlias = bool | Iterable[bool]


class Rule:
    scenario: ClassVar[str] = ""
    meta: ClassVar[bool] = False
    watches: ClassVar[tuple[str, ...]] = ()
    # Runs first in every activation it is in, never cut by N or F (docs/ENGINE.md).
    safety: ClassVar[bool] = False
    # The robot this rule works for (None: every robot, or none; meta rules): an activation
    # woken by one robot's notifications runs that robot's rules and the robot-less ones.
    robot_id: str | None = None

    # Set by the engine after step 2 (the thesis' local variable "activated").
    activated: bool = False

    # Filled in per class by __init_subclass__: which steps are overridden, which are async.
    _steps: ClassVar[dict[str, tuple[bool, bool]]] = {}

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        steps = {}
        for step in ("data_acquisition", "actions"):
            method = getattr(cls, step)
            overridden = method is not getattr(Rule, step)
            steps[step] = (overridden, inspect.iscoroutinefunction(method))
        cls._steps = steps

    @property
    def name(self) -> str:
        """The rule type's name, as it appears in logs and engine_stats."""
        return type(self).__name__

    def data_acquisition(self) -> Any:
        """Step 1: read what the rule needs into attributes (may be ``async def``)."""
        return None

    def activation_guards(self) -> Tests:
        """Step 2: AND-ed tests on what was acquired; sets ``activated``."""
        return True

    def conditions(self) -> Tests:
        """Step 3: AND-ed tests; actions run only if these hold too."""
        return True

    def actions(self) -> Any:
        """Step 4: do the work (may be ``async def``)."""
        return None

    def rule_generation(self) -> Iterable[Rule]:
        """Step 5: rules to append to the next queue; runs even when not activated."""
        return ()

    def discarded(self, step: str) -> None:
        """The engine discarded this rule on an error in ``step`` (no rule generation ran).

        A hook for whoever keeps the rule alive (common.engine.supervisor); it must not
        raise. The default does nothing.
        """

    def clone(self) -> Rule:
        """A fresh copy of this rule for the next activation (shallow; ``activated`` reset)."""
        twin = copy.copy(self)
        twin.activated = False
        return twin

    def __repr__(self) -> str:
        return f"<{self.name} scenario={self.scenario or '-'}>"

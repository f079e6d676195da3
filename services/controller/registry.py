"""The controller scenarios by name: the names a strategy's ``controller_scenarios`` uses.

To add a scenario: write a :class:`~services.controller.scenario.ControllerScenario` subclass
in its own module (``scenario`` = its name, ``priority``, ``decide``) and register it below.
The meta-controller starts it for every robot whose strategy names it; no other change.
"""

from __future__ import annotations

from services.controller.avoid_left import AvoidLeft
from services.controller.avoid_right import AvoidRight
from services.controller.safety_stop import SafetyStop
from services.controller.scenario import ControllerScenario

SCENARIOS: dict[str, type[ControllerScenario]] = {}


def register(cls: type[ControllerScenario]) -> type[ControllerScenario]:
    """Make ``cls`` selectable by its ``scenario`` name (usable as a class decorator)."""
    name = cls.scenario
    if not name:
        raise ValueError(f"{cls.__name__} has no scenario name")
    if SCENARIOS.get(name, cls) is not cls:
        raise ValueError(f"controller scenario {name!r} is already registered")
    SCENARIOS[name] = cls
    return cls


for _builtin in (AvoidLeft, AvoidRight, SafetyStop):
    register(_builtin)

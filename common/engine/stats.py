"""Per-rule-type statistics the engine keeps and services publish to ``engine_stats``."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from common.engine.trigger import NOTIFICATION, RULE


@dataclass
class RuleStats:
    """Counters for one rule type.

    ``executed``: rules of this type run; ``activated``: whose guards held; ``acted``: whose
    actions completed; ``errors``: whose acquisition, tests, actions or generation raised or
    returned something invalid. Times are wall-clock seconds per execution.
    """

    rule_type: str
    scenario: str = ""
    executed: int = 0
    activated: int = 0
    acted: int = 0
    errors: int = 0
    total_time_s: float = 0.0
    max_time_s: float = 0.0

    def record_time(self, seconds: float) -> None:
        self.total_time_s += seconds
        if seconds > self.max_time_s:
            self.max_time_s = seconds

    @property
    def mean_time_s(self) -> float:
        return self.total_time_s / self.executed if self.executed else 0.0

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class EngineCounters:
    """Engine-wide counters: activations, what started them and what they ran.

    ``full_activations`` ran every rule in the queue (the thesis' algorithm);
    ``focused_activations`` ran the robot-less rules and those of the robots their wakes
    named; ``out_of_focus`` counts the rules a focused activation passed over (they kept
    their place). ``activations`` = full + focused.
    """

    activations: int = 0
    full_activations: int = 0
    focused_activations: int = 0
    out_of_focus: int = 0
    woken_by_notification: int = 0
    woken_by_period: int = 0
    woken_by_rule: int = 0
    rules_run: int = 0
    capped_by_n: int = 0
    capped_by_f: int = 0
    meta_reseeded: int = 0
    hook_errors: int = 0  # activation-end hooks that raised (Engine.at_activation_end)
    safety_run: int = 0  # safety rules run first in their activation (Rule.safety)
    over_budget: int = 0  # rule runs longer than EngineSettings.rule_budget_s

    def woken_by(self, reason: str) -> None:
        """Count an activation started by ``reason`` (common.engine.trigger: NOTIFICATION,
        RULE or PERIOD)."""
        if reason == NOTIFICATION:
            self.woken_by_notification += 1
        elif reason == RULE:
            self.woken_by_rule += 1
        else:
            self.woken_by_period += 1

    def as_dict(self) -> dict[str, int]:
        return asdict(self)

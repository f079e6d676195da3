"""Rules over their time budget: logged with the rule, its time and the budget, once per
rule type per window, not once per run.

The engine cannot stop a rule's synchronous Python half-way, so a rule's work must be
bounded by construction (a scenario fits what its params ask to a budget: pnav_local's dwa,
for one). What the engine does is tell: a run longer than ``EngineSettings.rule_budget_s``
is counted (``EngineCounters.over_budget``); the first of a rule type is logged at once
(WARNING), later ones are folded into one line per ``window_s`` of wall time with their
count and the longest (``... over its time budget N times in the last T s``), logged on the
next over-run after the window or when :meth:`BudgetLog.flush` finds one due.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from common.engine.errorlog import WINDOW_S

# Rule types remembered (a service has a dozen): beyond it the table starts afresh.
MAX_TYPES = 256


@dataclass
class _Over:
    logged_at: float
    runs: int = 0  # since the last line logged
    longest_s: float = 0.0  # of those runs
    robot: str | None = None  # the robot of the longest
    budget_s: float = 0.0


@dataclass(eq=False)
class BudgetLog:
    logger: logging.Logger
    engine: str
    window_s: float = WINDOW_S
    clock: Callable[[], float] = time.monotonic
    _seen: dict[tuple[str, str], _Over] = field(default_factory=dict, init=False, repr=False)
    # rule types with over-runs not yet logged: flush is free when 0
    _pending: int = field(default=0, init=False, repr=False)

    def over(
        self, rule: str, scenario: str, robot: str | None, seconds: float, budget_s: float
    ) -> None:
        """A run of ``rule`` took ``seconds``, more than ``budget_s``."""
        now = self.clock()
        key = (rule, scenario)
        seen = self._seen.get(key)
        if seen is None:
            if len(self._seen) >= MAX_TYPES:
                self.flush(force=True)
                self._seen.clear()
            self._seen[key] = _Over(now)
            self._log(key, 1, seconds, budget_s, robot, None)
            return
        if seen.runs == 0:
            self._pending += 1
        seen.runs += 1
        if seconds >= seen.longest_s:
            seen.longest_s, seen.robot = seconds, robot
        seen.budget_s = budget_s
        if now - seen.logged_at >= self.window_s:
            self._summarise(key, seen, now)

    def flush(self, *, force: bool = False) -> None:
        """Log the over-runs whose window has passed (every one with ``force``)."""
        if not self._pending:
            return
        now = self.clock()
        for key, seen in self._seen.items():
            if seen.runs and (force or now - seen.logged_at >= self.window_s):
                self._summarise(key, seen, now)

    def _summarise(self, key: tuple[str, str], seen: _Over, now: float) -> None:
        self._log(key, seen.runs, seen.longest_s, seen.budget_s, seen.robot, now - seen.logged_at)
        seen.runs, seen.longest_s, seen.robot = 0, 0.0, None
        seen.logged_at = now
        self._pending -= 1

    def _log(
        self,
        key: tuple[str, str],
        runs: int,
        seconds: float,
        budget_s: float,
        robot: str | None,
        window: float | None,
    ) -> None:
        rule, scenario = key
        who = f"rule {rule}" + (f" (robot {robot})" if robot else "")
        times = f"{seconds * 1e3:.1f} ms > {budget_s * 1e3:.1f} ms"
        if window is None:
            later = f"later ones: one line per {self.window_s:.0f} s"
            text = f"{who} over its time budget: {times} ({later})"
        else:
            last = f"{runs} time{'s' if runs != 1 else ''} in the last {window:.1f} s"
            text = f"{who} over its time budget {last}: longest {times}"
        extra = {
            "rule": rule,
            "scenario": scenario,
            "engine": self.engine,
            "robot": robot,
            "time_ms": round(seconds * 1e3, 1),
            "budget_ms": round(budget_s * 1e3, 1),
            "repeated": runs,
        }
        self.logger.warning(text, extra=extra)

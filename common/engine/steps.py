"""Running one rule's five steps (thesis figure 3.2), with its statistics and its errors.

:class:`StepRunner` runs a rule for its :class:`~common.engine.Engine` (``engine.steps``, a
collaborator the engine makes): data acquisition, activation guards, conditions, actions,
rule generation; a test that is not a bool (or raises) counts as false; an error in
acquisition, actions or generation discards the rule (``Rule.discarded`` is told; a meta rule
is re-seeded from its factory), unless it is one of the engine's ``fatal`` errors, which is
raised (the monolith's own plumbing failing). Errors are counted every time and logged once
per distinct error, then as a count now and then (common.engine.errorlog). A run longer than
the settings' rule budget is counted and logged the same way (common.engine.budget). The
queues and when activations run are the Engine's.
"""

from __future__ import annotations

import asyncio
import logging
import sys
import time
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any

from common.config import EngineSettings
from common.engine.budget import BudgetLog
from common.engine.errorlog import ErrorLog, error_key
from common.engine.rule import Rule
from common.engine.stats import EngineCounters, RuleStats

RuleFactory = Callable[[], Rule]


class StepRunner:
    """Runs rules' five steps into the engine's ``next`` queue, with their statistics."""

    def __init__(
        self,
        name: str,
        settings: EngineSettings,
        next_queue: deque[Rule],
        counters: EngineCounters,
        error_log: ErrorLog,
        budget_log: BudgetLog,
        meta_factories: dict[type[Rule], RuleFactory],
        fatal: tuple[type[Exception], ...] = (),
    ) -> None:
        self.name = name
        self.settings = settings
        self.next = next_queue  # the engine's: generated rules go to its end
        self.counters = counters
        self.error_log = error_log
        self.budget_log = budget_log
        self.meta_factories = meta_factories  # the engine's: a meta rule lost is re-seeded
        self.fatal = fatal  # errors raised, never discarded
        self.stats: dict[type[Rule], RuleStats] = {}

    async def run(self, rule: Rule) -> None:
        """Run the five steps of ``rule`` (thesis figure 3.2) and file its statistics."""
        cls = type(rule)
        stats = self.stats.get(cls)
        if stats is None:
            stats = self.stats[cls] = RuleStats(rule.name, cls.scenario)
        started = time.perf_counter()
        stats.executed += 1
        if not await self._step(rule, "data_acquisition", "data acquisition", stats, started):
            return
        rule.activated = self._tests(rule, stats, rule.activation_guards, "activation guard")
        if rule.activated:
            stats.activated += 1
            if self._tests(rule, stats, rule.conditions, "condition"):
                if not await self._step(rule, "actions", "actions", stats, started):
                    return
                stats.acted += 1

        self._generate(rule, stats)
        self._timed(rule, stats, started)

    async def _step(
        self, rule: Rule, step: str, what: str, stats: RuleStats, started: float
    ) -> bool:
        """Run ``rule``'s ``step`` (data_acquisition or actions) if its class has one; False
        after an error, the rule then discarded and its run's time filed."""
        overridden, is_async = type(rule)._steps[step]
        if not overridden:
            return True
        try:
            result = getattr(rule, step)()
            if is_async:
                await result
        except asyncio.CancelledError:
            raise
        except Exception:
            self._discard_on_error(rule, stats, what)
            self._timed(rule, stats, started)
            return False
        return True

    def _timed(self, rule: Rule, stats: RuleStats, started: float) -> None:
        """File the run's time; a run over the rule budget is counted and logged."""
        seconds = time.perf_counter() - started
        stats.record_time(seconds)
        budget = self.settings.rule_budget_s
        if seconds > budget:
            self.counters.over_budget += 1
            self.budget_log.over(rule.name, rule.scenario, rule.robot_id, seconds, budget)

    def _tests(self, rule: Rule, stats: RuleStats, step: Callable[[], Any], what: str) -> bool:
        """Evaluate AND-ed tests; anything but True (or an exception) counts as false."""
        try:
            result = step()
            if result is True:
                return True
            if result is False:
                return False
            if isinstance(result, Iterable) and not isinstance(result, (str, bytes)):
                for test in result:
                    if test is not True:
                        if test is not False:
                            self._invalid(rule, stats, what, test)
                        return False
                return True
            self._invalid(rule, stats, what, result)
        except Exception as exc:
            stats.errors += 1
            self._report(rule, what, f"{what} raised {_describe(exc)}; counted as false", exc)
        return False

    def _invalid(self, rule: Rule, stats: RuleStats, what: str, value: object) -> None:
        stats.errors += 1
        self._report(
            rule,
            what,
            f"{what} returned {value!r}, not a bool; counted as false",
            detail=f"not a bool: {type(value).__qualname__}",
        )

    def _generate(self, rule: Rule, stats: RuleStats) -> None:
        try:
            generated = rule.rule_generation()
            if generated is None:
                return
            for new in generated:
                if isinstance(new, Rule):
                    self.next.append(new)
                else:
                    stats.errors += 1
                    self._report(
                        rule,
                        "rule generation",
                        f"rule generation produced {new!r}, not a Rule; ignored",
                        detail=f"not a Rule: {type(new).__qualname__}",
                    )
        except Exception:
            self._discard_on_error(rule, stats, "rule generation")

    def _where(self, rule: Rule) -> dict[str, str]:
        """A log record's ``extra``: which rule of which engine."""
        return {"rule": rule.name, "scenario": rule.scenario, "engine": self.name}

    def _report(
        self,
        rule: Rule,
        step: str,
        message: str,
        exc: BaseException | None = None,
        *,
        detail: str = "",
        level: int = logging.ERROR,
    ) -> None:
        """Log an error of ``rule`` once per distinct error, then a count now and then
        (common.engine.errorlog): a rule failing on every tick must not flood the log."""
        key = error_key(type(rule), step, exc, detail)
        self.error_log.report(key, level, message, self._where(rule), exc_info=exc)

    def _discard_on_error(self, rule: Rule, stats: RuleStats, step: str) -> None:
        """Count, log and discard ``rule`` after an error in ``step``; call it inside the
        ``except`` that caught the error. A ``fatal`` error is raised instead."""
        exc = sys.exc_info()[1]
        if exc is not None and isinstance(exc, self.fatal):
            raise exc
        stats.errors += 1
        what = _describe(exc) if exc is not None else "unknown error"
        self._report(rule, step, f"error in {step}; rule discarded: {what}", exc)
        try:
            rule.discarded(step)
        except Exception as hook_exc:
            self._report(
                rule, "discarded hook", f"discarded hook raised {_describe(hook_exc)}", hook_exc
            )
        factory = self.meta_factories.get(type(rule))
        if factory is not None:
            self.next.append(factory())
            self.counters.meta_reseeded += 1
            self._report(
                rule,
                "re-seed",
                "meta rule re-seeded after an error",
                detail=step,
                level=logging.WARNING,
            )


def _describe(exc: BaseException) -> str:
    """``ValueError: actuator refused``: the one-line form of an exception."""
    text = str(exc)
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__

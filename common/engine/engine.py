"""The rule-running system: two FIFO queues, N rules or F seconds per activation.

Semantics (DESIGN.md section 3, thesis section 3.2):

- ``current`` holds the rules of this activation, ``next`` the rules generated during it.
- One activation runs rules from the head of ``current`` until it is empty, or N rules have
  run, or F seconds have elapsed (checked between rules: a running rule is never
  interrupted). Then ``next`` is appended to ``current`` (so leftovers from the N or F cap run
  first next time) and ``next`` is emptied.
- :meth:`Engine.run` starts an activation every F seconds, or at once when :meth:`wake` is
  called (a Zenoh notification on a watched table), and always leaves at least P seconds
  between the end of one activation and the start of the next.
- Every rule is run once and discarded. Rules enter the system through :meth:`add` (end of
  ``current``) or a rule's generation step (end of ``next``).

In a lockstep run (common.lockstep) F is counted in sim time and checked when a sim clock
message comes, and after every activation that left nothing pending the engine reports its
service quiet: :meth:`Engine.run` then follows ``_run_lockstep``.

Our one addition to the thesis: a meta rule (``Rule.meta``) that is discarded because of an
error would silently end its meta scenario. The engine re-seeds it from the factory given to
:meth:`add_meta`, logs that it did, and counts it.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import deque
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any

from common.config import EngineSettings
from common.engine.rule import Rule
from common.engine.stats import EngineCounters, RuleStats

if TYPE_CHECKING:
    from common.lockstep import Ledger

log = logging.getLogger("pnav.engine")

RuleFactory = Callable[[], Rule]


class Engine:
    def __init__(self, settings: EngineSettings | None = None, name: str = "engine") -> None:
        self.settings = settings or EngineSettings()
        self.name = name
        self.current: deque[Rule] = deque()
        self.next: deque[Rule] = deque()
        self.counters = EngineCounters()
        self._stats: dict[type[Rule], RuleStats] = {}
        self._meta_factories: dict[type[Rule], RuleFactory] = {}
        self._wake: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stopping = False
        self._woken = False
        self._hurried = False
        self._running = False
        self.clock: Callable[[], float] = time.monotonic
        # set (with ``clock`` on sim time) when the service takes part in a lockstep run
        self.ledger: Ledger | None = None

    # -- putting rules in ------------------------------------------------------------------
    def add(self, rule: Rule) -> None:
        """Append ``rule`` to the end of the current queue."""
        if not isinstance(rule, Rule):
            raise TypeError(f"Engine.add() takes a Rule, got {type(rule).__name__}")
        self.current.append(rule)

    def add_meta(self, factory: RuleFactory) -> Rule:
        """Seed a meta scenario: add ``factory()`` now, and again if its rule dies of an error."""
        rule = factory()
        if not rule.meta:
            raise TypeError(f"{rule.name} is not a meta rule (set `meta = True` on its class)")
        self._meta_factories[type(rule)] = factory
        self.add(rule)
        return rule

    @property
    def watched_tables(self) -> tuple[str, ...]:
        """Tables named in ``watches`` by the meta rules seeded so far, sorted."""
        tables = {table for cls in self._meta_factories for table in cls.watches}
        return tuple(sorted(tables))

    # -- one activation --------------------------------------------------------------------
    async def activation(self) -> int:
        """Run one activation; return how many rules ran."""
        max_rules = self.settings.max_rules
        deadline = self.clock() + self.settings.period_s
        current = self.current
        ran = 0
        while current:
            if ran >= max_rules:
                self.counters.capped_by_n += 1
                break
            if ran and self.clock() >= deadline:
                self.counters.capped_by_f += 1
                break
            await self.run_rule(current.popleft())
            ran += 1
        current.extend(self.next)
        self.next.clear()
        self.counters.activations += 1
        self.counters.rules_run += ran
        return ran

    async def run_rule(self, rule: Rule) -> None:
        """Run the five steps of ``rule`` (thesis figure 3.2) and file its statistics."""
        cls = type(rule)
        stats = self._stats.get(cls)
        if stats is None:
            stats = self._stats[cls] = RuleStats(rule.name, cls.scenario)
        started = time.perf_counter()
        stats.executed += 1
        steps = cls._steps
        try:
            overridden, is_async = steps["data_acquisition"]
            if overridden:
                result = rule.data_acquisition()
                if is_async:
                    await result
        except asyncio.CancelledError:
            raise
        except Exception:
            self._discard_on_error(rule, stats, "data acquisition")
            stats.record_time(time.perf_counter() - started)
            return

        rule.activated = self._tests(rule, stats, rule.activation_guards, "activation guard")
        if rule.activated:
            stats.activated += 1
            if self._tests(rule, stats, rule.conditions, "condition"):
                try:
                    overridden, is_async = steps["actions"]
                    if overridden:
                        result = rule.actions()
                        if is_async:
                            await result
                except asyncio.CancelledError:
                    raise
                except Exception:
                    self._discard_on_error(rule, stats, "actions")
                    stats.record_time(time.perf_counter() - started)
                    return
                stats.acted += 1

        self._generate(rule, stats)
        stats.record_time(time.perf_counter() - started)

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
        except Exception:
            stats.errors += 1
            log.exception(
                "%s raised; counted as false",
                what,
                extra={"rule": rule.name, "scenario": rule.scenario, "engine": self.name},
            )
        return False

    def _invalid(self, rule: Rule, stats: RuleStats, what: str, value: object) -> None:
        stats.errors += 1
        log.error(
            "%s returned %r, not a bool; counted as false",
            what,
            value,
            extra={"rule": rule.name, "scenario": rule.scenario, "engine": self.name},
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
                    log.error(
                        "rule generation produced %r, not a Rule; ignored",
                        new,
                        extra={"rule": rule.name, "scenario": rule.scenario, "engine": self.name},
                    )
        except Exception:
            self._discard_on_error(rule, stats, "rule generation")

    def _discard_on_error(self, rule: Rule, stats: RuleStats, step: str) -> None:
        stats.errors += 1
        log.exception(
            "error in %s; rule discarded",
            step,
            extra={"rule": rule.name, "scenario": rule.scenario, "engine": self.name},
        )
        try:
            rule.discarded(step)
        except Exception:
            log.exception(
                "discarded hook raised",
                extra={"rule": rule.name, "scenario": rule.scenario, "engine": self.name},
            )
        factory = self._meta_factories.get(type(rule))
        if factory is not None:
            self.next.append(factory())
            self.counters.meta_reseeded += 1
            log.warning(
                "meta rule re-seeded after an error",
                extra={"rule": rule.name, "scenario": rule.scenario, "engine": self.name},
            )

    # -- statistics --------------------------------------------------------------------------
    def stats(self) -> list[RuleStats]:
        """A snapshot of the statistics per rule type (copies; safe to keep)."""
        return [RuleStats(**s.as_dict()) for s in self._stats.values()]

    def stats_for(self, rule_type: type[Rule]) -> RuleStats:
        return self._stats.get(rule_type) or RuleStats(rule_type.__name__, rule_type.scenario)

    # -- the activation loop ---------------------------------------------------------------
    def wake(self) -> None:
        """Start an activation as soon as possible (call on the engine's loop)."""
        self._woken = True
        if self._wake is not None:
            self._wake.set()

    def hurry(self) -> None:
        """Start the next activation as soon as the one under way ends.

        For a rule that generated target rules which should not wait for the next
        notification or for F (they go to ``next``, so they run in the next activation).
        """
        self._hurried = True
        if self._wake is not None:
            self._wake.set()

    def note_threadsafe(self) -> None:
        """A notification came (any thread): the flag is set before this returns, so a
        lockstep report taken after it sees the activation owed (see ``_run_lockstep``)."""
        self._woken = True
        self.poke_threadsafe()

    def poke_threadsafe(self) -> None:
        """Make the loop look again (any thread): in lockstep, after every counted receipt
        (a clock message may make F due; a quiet engine reports)."""
        loop, event = self._loop, self._wake
        if loop is not None and event is not None:
            try:
                loop.call_soon_threadsafe(event.set)
            except RuntimeError:
                pass  # loop closed while shutting down

    def wake_threadsafe(self) -> None:
        """:meth:`wake` from any thread, e.g. a Zenoh callback."""
        loop = self._loop
        if loop is not None:
            try:
                loop.call_soon_threadsafe(self.wake)
            except RuntimeError:
                pass  # loop closed while shutting down

    async def run(self) -> None:
        """Run activations until :meth:`stop`; the activation under way always completes."""
        if self._running:
            raise RuntimeError(f"engine {self.name} is already running")
        self._running = True
        self._loop = asyncio.get_running_loop()
        self._wake = asyncio.Event()
        period, pause = self.settings.period_s, self.settings.pause_s
        try:
            if self.ledger is not None:
                await self._run_lockstep(self.ledger)
                return
            while not self._stopping:
                self._wake.clear()
                self._woken = self._hurried = False
                started = self.clock()
                await self.activation()
                if pause > 0:
                    await asyncio.sleep(pause)
                if self._stopping:
                    break
                if not (self._woken or self._hurried):
                    remaining = started + period - self.clock()
                    if remaining > 0:
                        try:
                            await asyncio.wait_for(self._wake.wait(), remaining)
                        except TimeoutError:
                            pass
                if self._woken:
                    self.counters.woken_by_notification += 1
                elif self._hurried:
                    self.counters.woken_by_rule += 1
                else:
                    self.counters.woken_by_period += 1
        finally:
            self._running = False
            self._stopping = False

    async def _run_lockstep(self, ledger: Ledger) -> None:
        """Activations on notifications, hurry, and F in sim time; a report when quiet.

        The mark is taken before the flags are read: a notification counted in it set
        ``_woken`` before it was counted, so it is either consumed by the activation that
        follows (which reads the database after the row was committed) or still owed. A
        report therefore never covers a notification no activation has seen.
        """
        assert self._wake is not None
        started = -float("inf")
        while not self._stopping:
            self._wake.clear()
            mark = ledger.mark()
            woken, hurried = self._woken, self._hurried
            if woken or hurried or self.clock() >= started + self.settings.period_s:
                self._woken = self._hurried = False
                started = self.clock()
                await self.activation()
                if woken:
                    self.counters.woken_by_notification += 1
                elif hurried:
                    self.counters.woken_by_rule += 1
                else:
                    self.counters.woken_by_period += 1
                continue  # look again: what came meanwhile, a hurry, a report
            if ledger.report_if_settled(mark):
                await self._wake.wait()

    def stop(self) -> None:
        """Ask :meth:`run` to return after the activation under way (drain, don't cut)."""
        self._stopping = True
        if self._wake is not None:
            self._wake.set()

    @property
    def running(self) -> bool:
        return self._running

    def __len__(self) -> int:
        return len(self.current) + len(self.next)


def rules_in(rules: Iterable[Rule]) -> list[str]:
    """Names of rules, in order (handy in tests and logs)."""
    return [r.name for r in rules]

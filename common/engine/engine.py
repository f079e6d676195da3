"""The rule-running system: two FIFO queues, N rules or F seconds per activation.

Semantics (thesis section 3.2; docs/ENGINE.md says it all in full):

- ``current`` holds the rules of this activation, ``next`` the rules generated during it.
  An activation runs rules from the head of ``current`` until it is empty, N rules ran or F
  elapsed (checked between rules), then appends ``next`` to ``current``. Every rule runs
  once and is discarded; rules enter through :meth:`Engine.add` or a rule's generation.
- :meth:`Engine.run` starts an activation when its *trigger* says (common.engine.trigger:
  F, P, :meth:`Engine.wake`, :meth:`Engine.hurry`; in a lockstep run F in sim time and a
  quiet report when nothing is due, common.lockstep). F is counted on the engine's clock.

Our additions to the thesis:

- A meta rule (``Rule.meta``) discarded because of an error is re-seeded from the factory
  given to :meth:`Engine.add_meta`, logged and counted.
- Activation-end hooks (:meth:`Engine.at_activation_end`): awaited after an activation's
  last rule and before it counts as ended (``under_way``), so a store that defers its rules'
  writes sends them all in one round trip, still inside the activation.
- Per-robot wake-ups. ``wake(robot)`` and ``hurry(robot)`` record the robot they are about
  (None: anything). An activation started only by wakes and hurries that all named robots
  is *focused* on those robots: it runs, in queue order, the rules whose ``Rule.robot_id``
  is None or in the focus; every other rule keeps its place in ``current``, ahead of what
  the activation generates (as leftovers of the N cap do). N counts the rules that ran, F
  bounds the activation as before. Any other activation (the first one, one started by F,
  or by a robot-less wake or hurry) is *full*: exactly the thesis' algorithm. F, the
  fallback, is counted from the start of the last full activation, so every rule still runs
  at least every F under a stream of one robot's wakes. A focused activation that passed
  over no rule ran what a full one would have, and counts as full for F. An activation cut
  by N or F makes the next one full: what the cut left runs first, as in the thesis.
- Safety rules first (``Rule.safety``): an activation runs the safety rules it holds (in its
  focus) before any other rule but the meta rules at the head of the queue (they say which
  scenarios run: the controller's ends a dropped safety_stop before it reads a new scan),
  in queue order, and N and F never cut them; then the others as above, the first of them
  always running. So no robot's safety_stop waits behind another scenario's computation of
  that activation, and one that runs over F cuts the rest, not the safety rules of the next.
- A rule run over ``settings.rule_budget_s`` is counted and logged, once per rule type per
  10 s (common.engine.budget): the engine cannot stop synchronous Python, so a rule's work
  is bounded by construction, and F cuts what comes after it.
- Long-lived target rules are :class:`~common.engine.behaviour.Behaviour` objects, one object
  from ``initialise`` to ``terminate`` (no clone); :meth:`Engine.close` ends those still
  running when the service stops. One rule's five steps are run by ``steps``, a
  :class:`~common.engine.steps.StepRunner` the engine owns.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import deque
from collections.abc import Awaitable, Callable, Iterable

from common.config import EngineSettings
from common.engine.behaviour import STOPPED, Behaviour
from common.engine.budget import BudgetLog
from common.engine.errorlog import ErrorLog, error_key
from common.engine.rule import Rule
from common.engine.stats import EngineCounters, RuleStats
from common.engine.steps import RuleFactory, StepRunner
from common.engine.trigger import Clock, Periodic, Signals, Trigger
from common.errors import UsageError

log = logging.getLogger("pnav.engine")

ActivationEnd = Callable[[], Awaitable[None]]


class Engine:
    def __init__(
        self,
        settings: EngineSettings | None = None,
        name: str = "engine",
        *,
        trigger: Trigger | None = None,
        clock: Clock | None = None,
        fatal: tuple[type[Exception], ...] = (),
    ) -> None:
        """``trigger`` says when activations start (default :class:`Periodic`); ``clock``
        counts F, within an activation and between two (default: monotonic wall time);
        ``fatal``: errors a rule's step raises that stop the engine instead of discarding
        the rule (the monolith's own plumbing failing, not a rule's error)."""
        self._settings = settings or EngineSettings()
        self.name = name
        self.current: deque[Rule] = deque()
        self.next: deque[Rule] = deque()
        self.counters = EngineCounters()
        self.trigger: Trigger = trigger if trigger is not None else Periodic()
        self.clock: Clock = clock if clock is not None else time.monotonic
        self.signals = Signals()
        self._meta_factories: dict[type[Rule], RuleFactory] = {}
        self._running = False
        # errors are counted every time (stats), logged once per distinct error + a count
        self.error_log = ErrorLog(log)
        self.budget_log = BudgetLog(log, name)
        self.steps = StepRunner(
            name,
            self.settings,
            self.next,
            self.counters,
            self.error_log,
            self.budget_log,
            self._meta_factories,
            fatal,
        )
        # When the last full activation started, on ``clock`` (None: none yet): F counts
        # from it (see the module's docstring).
        self.full_started: float | None = None
        # The last activation was cut by N or F: the next one is full, so what the cut left
        # runs first, as in the thesis (a meta rule never overtakes the targets it made).
        self.cut = False
        # Resolved when the activation under way ends (None: none is): see under_way().
        self._ending: asyncio.Future[None] | None = None
        self._at_end: list[ActivationEnd] = []

    @property
    def settings(self) -> EngineSettings:
        """F, N, P and the rule budget."""
        return self._settings

    @settings.setter
    def settings(self, value: EngineSettings) -> None:
        # the steps time every rule against the budget: a new value reaches them too
        self._settings = value
        self.steps.settings = value

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

    def at_activation_end(self, hook: ActivationEnd) -> None:
        """Await ``hook()`` at the end of every activation, after its last rule and before
        the activation counts as ended (:meth:`under_way`), in the order added.

        For a store that defers the writes its rules ask for (one multi-row INSERT for the
        activation instead of a round trip per rule: docs/ARCHITECTURE.md, batching across
        robots). A hook owns its errors: one that raises is logged once per distinct error
        and counted (``counters.hook_errors``); the engine runs on.
        """
        self._at_end.append(hook)

    @property
    def watched_tables(self) -> tuple[str, ...]:
        """Tables named in ``watches`` by the meta rules seeded so far, sorted."""
        tables = {table for cls in self._meta_factories for table in cls.watches}
        return tuple(sorted(tables))

    # -- one activation --------------------------------------------------------------------
    async def activation(self, focus: frozenset[str] | None = None) -> int:
        """Run one activation; return how many rules ran. ``focus``: the robots whose rules
        run (with the robot-less ones); None: a full activation, every rule."""
        started = self.clock()
        deadline = started + self.settings.period_s
        self.cut = False
        ending = self._ending = asyncio.get_running_loop().create_future()
        try:
            if focus is None:
                ran = await self._run_all(deadline)
                passed_over = 0
                self.counters.full_activations += 1
            else:
                ran, passed_over = await self._run_focused(focus, deadline)
                self.counters.focused_activations += 1
                self.counters.out_of_focus += passed_over
            for hook in self._at_end:
                await self._run_hook(hook)
        finally:
            self._ending = None
            ending.set_result(None)
        if not passed_over:
            self.full_started = started
        self.current.extend(self.next)
        self.next.clear()
        self.counters.activations += 1
        self.counters.rules_run += ran
        self.error_log.flush()
        self.budget_log.flush()
        return ran

    async def _run_hook(self, hook: ActivationEnd) -> None:
        try:
            await hook()
        except Exception as exc:
            self.counters.hook_errors += 1
            where = getattr(hook, "__qualname__", repr(hook))
            key = error_key(type(getattr(hook, "__self__", hook)), f"end:{where}", exc)
            message = f"engine {self.name}: activation-end hook {where} failed: {exc!r}"
            self.error_log.report(key, logging.ERROR, message, {}, exc_info=exc)

    def under_way(self) -> asyncio.Future[None] | None:
        """A future resolved when the activation under way ends, or None when none is.

        Whoever stops acting for a robot (robot leases, common.lease) waits on it before
        telling anyone else: a rule that looked at ``owns`` before may still be writing
        for the robot until its activation ends. Rules of later activations see the robot
        as not owned when they look.
        """
        return self._ending

    async def _run_safety(self, focus: frozenset[str] | None) -> int:
        """Run the safety rules of ``current`` (those of ``focus`` and the robot-less ones;
        None: all) first, in queue order, uncut; the others keep their order. How many ran."""
        current = self.current
        if not any(rule.safety for rule in current):
            return 0
        first: list[Rule] = []
        rest: list[Rule] = []
        for rule in current:
            robot = rule.robot_id
            due = focus is None or robot is None or robot in focus
            (first if rule.safety and due else rest).append(rule)
        if first:
            current.clear()
            current.extend(rest)
            for rule in first:
                await self.steps.run(rule)
            self.counters.safety_run += len(first)
        return len(first)

    def _capped(self, ran: int, max_rules: int, deadline: float) -> bool:
        """Whether the activation stops here, at N rules run or past F (counted, and the
        activation marked cut); asked only once a rule that is not a safety rule ran."""
        if ran >= max_rules:
            self.counters.capped_by_n += 1
        elif self.clock() >= deadline:
            self.counters.capped_by_f += 1
        else:
            return False
        self.cut = True
        return True

    async def _run_all(self, deadline: float) -> int:
        """The thesis' activation: rules from the head of ``current`` until N or F (the
        safety rules moved up behind the meta rules at the head, and uncut)."""
        max_rules = self.settings.max_rules
        current = self.current
        ran = others = 0  # the first rule that is not a safety rule always runs
        safety_ran = False
        while current:
            if not safety_ran and not current[0].meta:
                ran += await self._run_safety(None)
                safety_ran = True
                continue
            if others and self._capped(ran, max_rules, deadline):
                break
            await self.steps.run(current.popleft())
            ran += 1
            others += 1
        if not safety_ran:
            ran += await self._run_safety(None)
        return ran

    async def _run_focused(self, focus: frozenset[str], deadline: float) -> tuple[int, int]:
        """A focused activation: the rules of ``focus`` and the robot-less ones, in queue
        order (the safety rules moved up behind the meta rules at the head, and uncut),
        until N or F; return (rules run, rules passed over). A rule passed over goes back to
        the head of ``current`` in its order, ahead of the rules not reached."""
        max_rules = self.settings.max_rules
        current = self.current
        passed: list[Rule] = []
        ran = others = 0
        safety_ran = False
        while current:
            rule = current[0]
            if not safety_ran and not rule.meta:
                ran += await self._run_safety(focus)
                safety_ran = True
                continue
            robot = rule.robot_id
            if robot is not None and robot not in focus:
                passed.append(current.popleft())
                continue
            if others and self._capped(ran, max_rules, deadline):
                break
            current.popleft()
            await self.steps.run(rule)
            ran += 1
            others += 1
        if not safety_ran:
            ran += await self._run_safety(focus)
        current.extendleft(reversed(passed))
        return ran, len(passed)

    # -- statistics --------------------------------------------------------------------------
    def stats(self) -> list[RuleStats]:
        """A snapshot of the statistics per rule type (copies; safe to keep)."""
        return [RuleStats(**s.as_dict()) for s in self.steps.stats.values()]

    def stats_for(self, rule_type: type[Rule]) -> RuleStats:
        return self.steps.stats.get(rule_type) or RuleStats(rule_type.__name__, rule_type.scenario)

    # -- the activation loop ---------------------------------------------------------------
    def wake(self, robot: str | None = None) -> None:
        """A notification came (about ``robot``, if it named one): start an activation as
        soon as the trigger allows, focused on ``robot`` unless something else asks for
        more (call on the engine's loop)."""
        signals = self.signals
        signals.ask(robot)
        signals.woken = True
        signals.look()

    def wake_threadsafe(self, robot: str | None = None) -> None:
        """:meth:`wake` from any thread, e.g. a Zenoh callback. The flag is set before this
        returns, so a lockstep count taken after it sees the activation owed."""
        signals = self.signals
        signals.ask(robot)
        signals.woken = True
        signals.look_threadsafe()

    def hurry(self, robot: str | None = None) -> None:
        """A rule generated target rules (for ``robot``, if they are one robot's) that should
        not wait for a notification or for F (they are in ``next``, so they run in the next
        activation): start it right after the one under way (call on the engine's loop, e.g.
        from a rule's actions). A rule that generated several robots' targets calls it once
        per robot, or once with None."""
        signals = self.signals
        signals.ask(robot)
        signals.hurried = True
        signals.look()

    def focus(self, first: bool = False) -> frozenset[str] | None:
        """What the activation about to start runs, from the robots the wakes and hurries
        named (read and forgotten: call after ``signals.take()``): their focus, or None for
        a full activation (the ``first``, a robot-less wake or hurry, none named, the last
        activation cut by N or F, or F passed since the last full activation started)."""
        robots = self.signals.take_focus()
        last = self.full_started
        if robots is None or first or last is None or self.cut:
            return None
        if self.clock() >= last + self.settings.period_s:
            return None
        return robots

    async def run(self) -> None:
        """Run activations until :meth:`stop`; the activation under way always completes.

        One loop: the trigger says when the next activation is due (F counted from the last
        full activation's start), the flags it saw name what started it (counted in
        ``counters.woken_by_*`` from the second one on) and the robots they named make it
        focused or full (:meth:`focus`).
        """
        if self._running:
            raise UsageError(f"engine {self.name} is already running")
        self._running = True
        signals = self.signals
        signals.attach()
        self.trigger.bind(signals)
        first = True
        try:
            while True:
                since = None if first else self.full_started
                await self.trigger.wait(signals, since, self.clock, self.settings)
                if signals.stopping:
                    break
                reason = signals.take()
                focus = self.focus(first)
                if not first:
                    self.counters.woken_by(reason)
                first = False
                await self.activation(focus)
        finally:
            self._running = False
            signals.stopping = False
            self.error_log.flush(force=True)  # the counts not yet logged
            self.budget_log.flush(force=True)

    def stop(self) -> None:
        """Ask :meth:`run` to return after the activation under way (drain, don't cut)."""
        self.signals.stopping = True
        self.signals.look()

    def close(self, why: str = STOPPED) -> int:
        """After :meth:`run`: end the behaviours still queued (``terminate(why)``, a hook that
        raises is logged); how many ended."""
        if self._running:
            raise UsageError(f"engine {self.name} still runs: stop it before closing")
        ended = 0
        for rule in (*self.current, *self.next):
            if not isinstance(rule, Behaviour):
                continue
            try:
                ended += rule.stop(why)
            except Exception:
                log.exception("terminate hook failed", extra={"engine": self.name})
                ended += 1
        return ended

    @property
    def running(self) -> bool:
        return self._running

    def __len__(self) -> int:
        return len(self.current) + len(self.next)


def rules_in(rules: Iterable[Rule]) -> list[str]:
    """Names of rules, in order (handy in tests and logs)."""
    return [r.name for r in rules]

"""When the engine starts an activation: its wake signals, the trigger seam, and the trigger
of a normal run.

:meth:`Engine.run <common.engine.Engine.run>` is one loop: ``await trigger.wait(...)``, then
an activation, again and again. The *trigger* decides when the next activation is due from
the wake signals (:class:`Signals`), F and P (``EngineSettings``), the start of the previous
activation and the engine's clock:

- :class:`Periodic` (a normal run): at once after a wake or a hurry, else F after the
  start of the last *full* activation, never sooner than P after the previous end; F on the
  wall clock;
- ``common.lockstep.LockstepTrigger`` (a lockstep run): on a wake, a hurry, or F in sim time,
  looked at on every counted message; when nothing is due it reports the service quiet.

A trigger only says *when*; what the activation runs (all rules, or those of the robots the
wakes named: :meth:`Signals.take_focus`, ``Engine.focus``) is the engine's business.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Protocol, cast

from common.config import EngineSettings
from common.errors import InternalError

Clock = Callable[[], float]

NOTIFICATION, RULE, PERIOD = "notification", "rule", "period"


class Signals:
    """What asks the engine for an activation, and the event its loop waits on.

    ``woken`` (a notification: ``Engine.wake``), ``hurried`` (a rule: ``Engine.hurry``) and
    ``stopping`` are plain flags: setting one is atomic, so another thread may set it
    before it asks the loop to look again (:meth:`look_threadsafe`).

    ``asked`` lists the robots the wakes and hurries named since the last
    :meth:`take_focus` (None: a robot-less one, "anything"). It is only ever appended to
    (atomic) and cut from its head, never replaced, so a name appended from another thread
    while the loop takes the list is either taken now or left for the next activation.
    """

    def __init__(self) -> None:
        self.woken = False
        self.hurried = False
        self.stopping = False
        self.asked: list[str | None] = []
        # A look asked and not yet cleared, and the future a waiting trigger sleeps on.
        # A plain future rather than ``wait_for(event.wait(), ...)``: that wraps every wait
        # in a task of its own, and a wake then takes three loop iterations to reach the
        # activation instead of one (docs/BENCHMARKS.md, "Where a hop's milliseconds go").
        self._looked = False
        self._waiter: asyncio.Future[None] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None

    @property
    def pending(self) -> bool:
        """A wake or a hurry is owed an activation."""
        return self.woken or self.hurried

    def attach(self) -> None:
        """Bind to the running loop (``Engine.run`` does it before its first wait)."""
        self._loop = asyncio.get_running_loop()
        self._looked = False

    def look(self) -> None:
        """Make a waiting trigger look again (on the engine's loop)."""
        if self._loop is None:
            return
        self._looked = True
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def look_threadsafe(self) -> None:
        """:meth:`look` from any thread (nothing before the loop runs, or once it closed)."""
        loop = self._loop
        if loop is not None:
            try:
                loop.call_soon_threadsafe(self.look)
            except RuntimeError:
                pass  # loop closed while shutting down

    def clear(self) -> None:
        """Forget the looks asked so far (read the flags after this, not before)."""
        self._looked = False

    async def wait(self, limit_s: float | None = None) -> bool:
        """Until a look is asked (True, and it is cleared) or ``limit_s`` passed (False)."""
        loop = self._loop
        if loop is None:
            raise InternalError("Signals.wait() before attach()")
        if not self._looked:
            waiter = self._waiter = loop.create_future()
            timer = None if limit_s is None else loop.call_later(limit_s, _expire, waiter)
            try:
                await waiter
            finally:
                self._waiter = None
                if timer is not None:
                    timer.cancel()
            if not self._looked:
                return False
        self._looked = False
        return True

    def ask(self, robot: str | None) -> None:
        """Record what a wake or a hurry is about (call before setting its flag: a flag
        seen set means its robot is already recorded)."""
        self.asked.append(robot)

    def take_focus(self) -> frozenset[str] | None:
        """The robots named since the last call, and forget them: None when a wake or hurry
        named none, or when none was recorded (a flag set directly, or a name taken by the
        previous activation while its flag was set again: a full activation is always safe).
        Call after :meth:`take`."""
        asked = self.asked
        count = len(asked)
        if count == 0:
            return None
        names = asked[:count]
        del asked[:count]  # what another thread appended meanwhile stays for the next
        robots = frozenset(names)
        if None in robots:
            return None
        return cast("frozenset[str]", robots)

    def take(self) -> str:
        """What starts the activation about to run (:data:`NOTIFICATION`, :data:`RULE` or
        :data:`PERIOD`); both flags are cleared: a wake from now on asks for another."""
        reason = NOTIFICATION if self.woken else RULE if self.hurried else PERIOD
        self.woken = self.hurried = False
        self.clear()
        return reason


def _expire(waiter: asyncio.Future[None]) -> None:
    """A wait's time limit passed (its look, if any, came first)."""
    if not waiter.done():
        waiter.set_result(None)


class Trigger(Protocol):
    """When the next activation starts (the engine's pluggable seam)."""

    def bind(self, signals: Signals) -> None:
        """Called by ``Engine.run`` on its loop, before the first :meth:`wait`."""

    async def wait(
        self, signals: Signals, since: float | None, clock: Clock, settings: EngineSettings
    ) -> None:
        """Return when the next activation is due, or as soon as ``signals.stopping``.

        ``since`` is the start of the last *full* activation on ``clock`` (None: none ran
        yet): F bounds the time between two full ones, however many focused ones ran in
        between. The engine reads and clears the wake flags (:meth:`Signals.take`) and the
        robots they named (:meth:`Signals.take_focus`) once this returns.
        """


class Periodic:
    """A normal run: the first activation at once; then, after P, at once if woken or
    hurried, else when F has passed since the last full activation started (F on
    ``clock``)."""

    def bind(self, signals: Signals) -> None:
        return None

    async def wait(
        self, signals: Signals, since: float | None, clock: Clock, settings: EngineSettings
    ) -> None:
        if since is None:
            return
        if settings.pause_s > 0:
            await asyncio.sleep(settings.pause_s)
        while not (signals.stopping or signals.pending):
            remaining = since + settings.period_s - clock()
            # a look without a flag (one whose wake an activation already served) waits on
            if remaining <= 0 or not await signals.wait(remaining):
                return

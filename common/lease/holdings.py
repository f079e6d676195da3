"""The robots whose lock a replica holds, and which of them it acts for: all of them but the
ones taken over from a holder that vanished, until their takeover wait is over (the package
docstring says why)."""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Iterable

from common import log

logger = logging.getLogger("pnav.lease")

Report = Callable[[frozenset[str], frozenset[str]], None]  # (gained, lost) acting robots


class Holdings:
    """``report(gained, lost)`` runs whenever the robots acted for change: a robot is lost
    when it is dropped (before the caller releases its lock), gained when it is added
    without a wait or when its wait ends (a timer on ``loop``)."""

    def __init__(self, report: Report, loop: asyncio.AbstractEventLoop | None = None) -> None:
        self.report = report
        self.loop = loop
        self.owned: set[str] = set()
        self.waiting: dict[str, float] = {}  # robot -> monotonic time it may be acted for
        self._timer: asyncio.TimerHandle | None = None

    def acting(self) -> frozenset[str]:
        return frozenset(self.owned.difference(self.waiting))

    def __contains__(self, robot: object) -> bool:
        return robot in self.owned and robot not in self.waiting

    def add(self, robot: str, wait_s: float) -> bool:
        """Its lock is ours; act for it now (True) or after ``wait_s``. A caller that gets
        True reports the gain itself, before its next await: the robot is acted for now."""
        self.owned.add(robot)
        if wait_s <= 0:
            return True
        self.waiting[robot] = time.monotonic() + wait_s
        self._schedule()
        return False

    def drop(self, robots: Iterable[str]) -> None:
        """Forget ``robots``, reporting the ones acted for as lost."""
        robots = set(robots) & self.owned
        if not robots:
            return
        acting = self.acting() & robots
        self.owned.difference_update(robots)
        for robot in robots:
            self.waiting.pop(robot, None)
        self._schedule()
        if acting:
            self.report(frozenset(), acting)

    def clear(self) -> frozenset[str]:
        """Forget every robot (reporting the acted-for ones lost); return all that were held."""
        held = frozenset(self.owned)
        self.drop(held)
        return held

    def promote(self) -> None:
        """Act for the robots whose wait is over."""
        now = time.monotonic()
        ready = frozenset(r for r, at in self.waiting.items() if at <= now)
        for robot in ready:
            del self.waiting[robot]
        self._schedule()
        if ready:
            log.event(logger, logging.INFO, "takeover wait over", robots=",".join(sorted(ready)))
            self.report(ready, frozenset())

    def _schedule(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if self.waiting and self.loop is not None:
            delay = min(self.waiting.values()) - time.monotonic()
            self._timer = self.loop.call_later(max(0.0, delay), self.promote)

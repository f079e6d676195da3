"""Log a rule's errors once per distinct error, then a count now and then, not once per tick.

A rule that keeps failing on the same input (a bad row it re-reads every activation) would
otherwise log the same traceback 20 to 100 times a second, burying everything else. The
engine still *counts* every error (``RuleStats.errors``); only the log lines are thinned.

A distinct error is (rule type, step, exception type, message). Its first occurrence is
logged in full, traceback included. Repeats are counted silently, and a one-line summary
``... (repeated N times in the last T s)`` is logged at most once per ``window_s`` (wall
time, whatever clock the engine's F uses: logs are read by people) per distinct error:
when a repeat comes after the window, or when :meth:`ErrorLog.flush` finds one due.
"""

from __future__ import annotations

import logging
import time
from collections import OrderedDict
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from common.outage import is_connection_error

WINDOW_S = 10.0
# Distinct errors remembered; beyond it the least recently logged is forgotten (its pending
# count is logged first), so a rule whose message varies forever cannot grow memory.
MAX_DISTINCT = 256

ErrorKey = tuple[type, str, str, str]


@dataclass
class _Seen:
    message: str
    level: int
    extra: Mapping[str, object]
    logged_at: float
    repeats: int = 0  # since the last line logged
    # the newest occurrence, when it says the database could not be reached: a summary of
    # such errors carries it, so that an outage (common/outage.py) folds it while it lasts
    lost_connection: BaseException | None = None


@dataclass(eq=False)
class ErrorLog:
    logger: logging.Logger
    window_s: float = WINDOW_S
    clock: Callable[[], float] = time.monotonic
    _seen: OrderedDict[ErrorKey, _Seen] = field(default_factory=OrderedDict, init=False, repr=False)
    # distinct errors with unlogged repeats: flush is free when 0
    _pending: int = field(default=0, init=False, repr=False)

    def report(
        self,
        key: ErrorKey,
        level: int,
        message: str,
        extra: Mapping[str, object],
        *,
        exc_info: BaseException | None = None,
    ) -> None:
        """An error occurred: log it if it is new, else count it (and summarise when due).
        ``message`` is already formatted; ``exc_info``: the exception, logged with its
        traceback the first time."""
        now = self.clock()
        seen = self._seen.get(key)
        if seen is None:
            if len(self._seen) >= MAX_DISTINCT:
                self._forget_oldest(now)
            self._seen[key] = _Seen(message, level, extra, now)
            self.logger.log(
                level,
                "%s (repeats: one line per %.0f s)",
                message,
                self.window_s,
                exc_info=exc_info,
                extra=dict(extra),
            )
            return
        if seen.repeats == 0:
            self._pending += 1
        seen.repeats += 1
        seen.lost_connection = exc_info if is_connection_error(exc_info) else None
        if now - seen.logged_at >= self.window_s:
            self._summarise(key, seen, now)

    def flush(self, *, force: bool = False) -> None:
        """Log the summary of every distinct error whose window has passed with repeats
        unlogged (call now and then, e.g. after each activation); ``force``: whether or not
        the window has passed (e.g. when the engine stops, so no count is lost)."""
        if not self._pending:
            return
        now = self.clock()
        for key, seen in list(self._seen.items()):
            if seen.repeats and (force or now - seen.logged_at >= self.window_s):
                self._summarise(key, seen, now)

    def _summarise(self, key: ErrorKey, seen: _Seen, now: float) -> None:
        self.logger.log(
            seen.level,
            "%s (repeated %d times in the last %.1f s)",
            seen.message,
            seen.repeats,
            now - seen.logged_at,
            extra={**seen.extra, "repeated": seen.repeats},
            exc_info=seen.lost_connection,
        )
        seen.repeats = 0
        seen.logged_at = now
        self._pending -= 1
        self._seen.move_to_end(key)

    def _forget_oldest(self, now: float) -> None:
        key, seen = next(iter(self._seen.items()))
        if seen.repeats:
            self._summarise(key, seen, now)
        del self._seen[key]


def error_key(rule_type: type, step: str, exc: BaseException | None, detail: str = "") -> ErrorKey:
    """The identity of an error: the rule's type, the step, the exception's type and message
    (or, for an invalid result with no exception, ``detail``)."""
    if exc is None:
        return (rule_type, step, "", detail)
    return (rule_type, step, type(exc).__qualname__, str(exc))

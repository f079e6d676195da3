"""A database outage, seen from one process: back off, say so once, say when it is over.

When Postgres goes away (the embedded one killed, restarting), every part of a service fails
on its next query: the engine's rules on every wake, the statistics loop, the lease
connection, the pool refilling its floor, the bridge's writers. Each would retry at its own
pace and log its own traceback. Instead, one :class:`Outage` per server in each process
(:func:`outage_for`, shared by all its pools):

- Connecting goes through :meth:`Outage.may_try` (common.db's pools use it as their connect
  function): while the database is down, one connection attempt is let through now and then
  (0.2 s, doubling to 2 s) and every other acquire fails at once with
  :class:`DatabaseUnavailable`, so nothing hammers a server that is not there.
- The first failure to connect logs one WARNING; while it lasts, one summary line every
  :attr:`Outage.window_s` at most; the first successful connection logs one INFO line with
  the outage's length and counts.
- :class:`FoldingFilter` (installed on the process's log handlers by common.runtime) folds,
  while the database is down, every WARNING or ERROR whose exception is a lost or refused
  connection into the outage's count: they would only repeat that the database is down.
  Such a line logged while the database is up (the first query to find its connection
  gone) keeps its message and the exception's one line, not asyncpg's traceback.

Nothing else changes: the callers' own retries (the engine re-running its rules, the lease
manager reconnecting) carry on and succeed once Postgres is back.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterable

import asyncpg

from common.errors import ConnectionFailure

logger = logging.getLogger("pnav.db")

PROBE_FIRST_S = 0.2
PROBE_MAX_S = 2.0
WINDOW_S = 5.0
# never folded: our own lines, and a process's last words (common.runtime's exit message)
_UNFOLDED = frozenset({"pnav.db", "pnav.runtime"})


class DatabaseUnavailable(ConnectionFailure):
    """Raised without trying while the database is known to be down (a probe is not due)."""


_CONNECTION_ERRORS: tuple[type[BaseException], ...] = (
    OSError,  # refused, reset, no socket
    asyncpg.PostgresConnectionError,  # includes "connection was closed in the middle..."
    asyncpg.CannotConnectNowError,  # starting up, recovering
    asyncpg.AdminShutdownError,
    asyncpg.CrashShutdownError,
    ConnectionFailure,  # ours, e.g. the lease connection could not be opened
    # a connection the server ended while it was idle: asyncpg sees the FATAL late and the
    # next query fails with "cannot switch to state ..." (MagicStack/asyncpg#1069, #784)
    asyncpg.InternalClientError,
)


def is_connection_error(exc: BaseException | None) -> bool:
    """Whether ``exc`` (or what caused it) says the database could not be reached."""
    for _ in range(6):
        if exc is None:
            return False
        if isinstance(exc, ConnectionFailure) and not isinstance(exc, DatabaseUnavailable):
            # ours wrap the real cause (or name a misconfiguration: then not an outage)
            exc = exc.__cause__
            continue
        if isinstance(exc, _CONNECTION_ERRORS):
            return True
        exc = exc.__cause__ or exc.__context__
    return False


class Outage:
    def __init__(
        self, window_s: float = WINDOW_S, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.window_s = window_s
        self.clock = clock
        self.since: float | None = None  # None: up
        self.failures = 0  # operations that failed during this outage
        self.folded = 0  # log lines folded into it
        self.outages = 0  # since the process started
        self._probe_delay = PROBE_FIRST_S
        self._next_probe = 0.0
        self._last_line = 0.0

    @property
    def down(self) -> bool:
        return self.since is not None

    def may_try(self) -> bool:
        """Whether to try connecting now (always, unless down and no probe is due); a
        caller told yes while down is the probe: the next is due after the back-off."""
        if self.since is None:
            return True
        now = self.clock()
        if now < self._next_probe:
            self.failures += 1
            self._maybe_summarise(now)
            return False
        self._next_probe = now + self._probe_delay
        self._probe_delay = min(self._probe_delay * 2, PROBE_MAX_S)
        return True

    def failed(self, exc: BaseException) -> None:
        """Connecting failed with ``exc`` (a connection error)."""
        now = self.clock()
        self.failures += 1
        if self.since is None:
            self.since = now
            self.outages += 1
            self._probe_delay = PROBE_FIRST_S
            self._next_probe = now + self._probe_delay
            self._last_line = now
            logger.warning(
                "database unreachable: %r; backing off (a retry every %.1f-%.0f s), "
                "one line per %.0f s until it is back",
                exc,
                PROBE_FIRST_S,
                PROBE_MAX_S,
                self.window_s,
            )
            return
        self._maybe_summarise(now)

    def recovered(self) -> None:
        """A connection was made: the outage, if any, is over."""
        if self.since is None:
            return
        now = self.clock()
        logger.info(
            "database back after %.1f s (%d operations failed, %d log lines folded)",
            now - self.since,
            self.failures,
            self.folded,
        )
        self.since = None
        self.failures = 0
        self.folded = 0

    def fold(self, record: logging.LogRecord) -> bool:
        """Whether ``record`` only repeats that the database is down (then it is counted)."""
        if self.since is None or record.levelno < logging.WARNING or record.name in _UNFOLDED:
            return False
        if not _about_connection(record):
            return False
        self.folded += 1
        self._maybe_summarise(self.clock())
        return True

    def _maybe_summarise(self, now: float) -> None:
        if self.since is None or now - self._last_line < self.window_s:
            return
        self._last_line = now
        logger.warning(
            "database still unreachable after %.0f s (%d operations failed, %d log lines folded)",
            now - self.since,
            self.failures,
            self.folded,
        )


def _about_connection(record: logging.LogRecord) -> bool:
    if record.exc_info and is_connection_error(record.exc_info[1]):
        return True
    args = record.args if isinstance(record.args, tuple) else ()
    return any(isinstance(a, BaseException) and is_connection_error(a) for a in args)


class FoldingFilter(logging.Filter):
    """A handler filter: drop what an outage (:meth:`Outage.fold`) folds; ``outages``: a
    fixed set (tests), else every server this process connects to (:func:`outage_for`)."""

    def __init__(self, outages: Iterable[Outage] | None = None) -> None:
        super().__init__()
        self._outages = list(outages) if outages is not None else None

    def filter(self, record: logging.LogRecord) -> bool:
        outages = self._outages if self._outages is not None else _OUTAGES.values()
        if any(outage.fold(record) for outage in outages):
            return False
        if record.exc_info and is_connection_error(record.exc_info[1]):
            # a lost or refused connection: its traceback is asyncpg's socket code, 30
            # lines that say nothing the exception's one line does not
            exc = record.exc_info[1]
            record.exc_info, record.exc_text = None, None
            record.__dict__.setdefault("error", repr(exc))
        return True


# one per server (DSN): a process may talk to more than one (tests, tools)
_OUTAGES: dict[str, Outage] = {}


def outage_for(dsn: str) -> Outage:
    """The outage state of the server ``dsn`` names, shared by every pool of this process."""
    outage = _OUTAGES.get(dsn)
    if outage is None:
        outage = _OUTAGES[dsn] = Outage()
    return outage


def fold_outage_logs() -> None:
    """Install :class:`FoldingFilter` on the root logger's handlers (once each)."""
    for handler in logging.getLogger().handlers:
        if not any(isinstance(f, FoldingFilter) for f in handler.filters):
            handler.addFilter(FoldingFilter())

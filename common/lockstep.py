"""Taking part in a lockstep run: count what is sent and received, report when quiet.

At ``--rate max`` a sim that only bounds how stale a decision may be (``--max-lag``) lets the
outcome depend on the scheduling of a dozen processes. In lockstep the sim steps only when
the whole stack is *quiet*: every message caused by what the sim published has been handled
and every command decided from it has reached the sim. The same world and seed then give the
same run on a quiet or a loaded machine (docs/SIM.md, "Lockstep"; CONTRACT.md, "Lockstep").

A participant (every process of the stack with PNAV_LOCKSTEP set; the sim is the judge) has
one :class:`Ledger`, made by ``Runtime.open`` and handed to whatever counts on it: the
subscriptions (``bus.subscribe(..., ledger=)``), the notifier (``bus.Notifier``), the sim
clock, the bridge's cmd_vel publisher and the engine's trigger (:class:`LockstepTrigger`).
Nothing finds it implicitly. The participant:

- counts, per key, the messages it publishes (``Ledger.sent_on``; common.bus's Notifier and
  the bridge's cmd_vel do it), and per subscription, per key, the messages it received and
  handled (``Ledger.received``; common.bus's subscribe helpers do it *after* the handler ran);
- when it is quiet (its engine ran an activation after the last notification, the bridge
  wrote the rows and relayed the commands), publishes on ``pnav/lockstep/{service}/{instance}``
  its counts: ``{"seq": n, "sent": {key: n}, "subs": [[key_expr, {key: n}], ...]}``.

A status reports a handling and the messages it caused together, and nothing is sent
except as the effect of a counted message (in lockstep the engines' period and the bridge's
watchdog run on sim-clock messages, which are counted): so when, in the newest status of
every participant, every subscription has received at least what all participants (and the
sim) say they sent on its keys, nothing is in flight anywhere. One look suffices: along any
chain of causes starting at the sim's own publications, the first participant whose newest
status does not cover its part shows fewer receipts than its predecessor reported sent.

How quiet is detected is the participant's business; the engine's :class:`LockstepTrigger`
and the bridge do it with :meth:`Ledger.mark` / :meth:`Ledger.report_if_settled`: take a
mark, make sure everything received up to it is handled, then report if nothing was
received since the mark.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any

import msgpack
import zenoh

from common.config import EngineSettings
from common.contract import keys
from common.engine.trigger import Clock, Signals

log = logging.getLogger("pnav.lockstep")


class Tally:
    """Receipts of one subscription, per key."""

    __slots__ = ("counts", "key_expr")

    def __init__(self, key_expr: str) -> None:
        self.key_expr = key_expr
        self.counts: dict[str, int] = {}


class Ledger:
    """One participant's counts and its status publisher (thread-safe); :meth:`close` it."""

    def __init__(
        self, session: zenoh.Session, service: str, instance: str, *, receipts: bool = True
    ) -> None:
        self.service = service
        self.instance = instance
        # A sender-only participant (a benchmark runner that writes a mission, then only
        # watches) does not count its subscriptions: the sim would wait for it to report them.
        self.receipts = receipts
        self.sent: dict[str, int] = {}
        self.tallies: list[Tally] = []
        self.reports = 0
        # called after every receipt (on the thread that counted it): wakes whoever reports
        self.listener: Callable[[], None] | None = None
        self._received = 0
        self._lock = threading.Lock()
        self._publisher = session.declare_publisher(
            keys.lockstep_key(service, instance),
            congestion_control=zenoh.CongestionControl.BLOCK,
            express=True,
        )

    def tally(self, key_expr: str) -> Tally | None:
        """A tally for a new subscription on ``key_expr`` (None: receipts are not counted)."""
        if not self.receipts:
            return None
        tally = Tally(key_expr)
        with self._lock:
            self.tallies.append(tally)
        return tally

    def received(self, tally: Tally, key: str) -> None:
        """A message on ``key`` was received and handled (call after the handler)."""
        with self._lock:
            tally.counts[key] = tally.counts.get(key, 0) + 1
            self._received += 1
        listener = self.listener
        if listener is not None:
            listener()

    def sent_on(self, key: str) -> None:
        with self._lock:
            self.sent[key] = self.sent.get(key, 0) + 1

    def mark(self) -> int:
        """How many messages were received so far (for :meth:`report_if_settled`)."""
        return self._received

    def report_if_settled(self, mark: int) -> bool:
        """Report the counts if nothing was received since ``mark``; whether it reported."""
        with self._lock:
            if self._received != mark:
                return False
            self.reports += 1
            body = {
                "seq": self.reports,
                "sent": dict(self.sent),
                "subs": [[t.key_expr, dict(t.counts)] for t in self.tallies],
            }
        try:
            self._publisher.put(msgpack.packb(body, use_bin_type=True))
        except Exception:  # the session is closing
            log.debug("lockstep status not sent", exc_info=True)
        return True

    def close(self) -> None:
        try:
            self._publisher.undeclare()
        except Exception:
            log.debug("lockstep publisher undeclare failed", exc_info=True)


class Status:
    """A participant's report as the sim reads it."""

    __slots__ = ("sent", "seq", "subs")

    def __init__(self, seq: int, sent: dict[str, int], subs: list[tuple[str, dict[str, int]]]):
        self.seq = seq
        self.sent = sent
        self.subs = subs

    @classmethod
    def decode(cls, payload: bytes) -> Status:
        """Raises ValueError on anything but a well-formed status."""
        try:
            body: Any = msgpack.unpackb(payload, raw=False)
            seq = int(body["seq"])
            sent = {str(k): int(n) for k, n in body["sent"].items()}
            subs = [(str(e), {str(k): int(n) for k, n in c.items()}) for e, c in body["subs"]]
        except Exception as exc:
            raise ValueError(f"malformed lockstep status: {exc}") from exc
        return cls(seq, sent, subs)


class LockstepTrigger:
    """The engine's trigger (common.engine.trigger) in a lockstep run; give the engine the
    sim clock with it (``Engine(..., trigger=LockstepTrigger(ledger), clock=sim.now)``).

    An activation is due on a wake, a hurry, or when F has passed in sim time since the last
    full activation started (``since``: a stream of one robot's wakes does not put off
    another robot's rules); there is no wall-clock period and P is not applied, so nothing
    runs while sim time stands still. Which rules it runs is the engine's business.
    Every counted receipt makes the trigger look again (a clock message may make F due).
    When nothing is due it reports the service quiet (:meth:`quiet`).
    """

    def __init__(self, ledger: Ledger) -> None:
        self.ledger = ledger

    def bind(self, signals: Signals) -> None:
        self.ledger.listener = signals.look_threadsafe

    async def wait(
        self, signals: Signals, since: float | None, clock: Clock, settings: EngineSettings
    ) -> None:
        """The mark is taken before the flags are read: a notification counted in it set
        its flag before it was counted (on the loop, or with ``Engine.wake_threadsafe``), so
        it is either served by the activation that follows (which reads the database after
        the row was committed) or still owed. A report never covers a notification no
        activation has seen."""
        while not signals.stopping:
            signals.clear()
            mark = self.ledger.mark()
            if signals.pending or since is None or clock() >= since + settings.period_s:
                return
            await self.quiet(signals, mark)

    async def quiet(self, signals: Signals, mark: int) -> None:
        """Nothing is due: report if nothing was received since ``mark``, then wait for the
        next look (a receipt, a wake, a hurry, a stop); else look again at once."""
        if self.ledger.report_if_settled(mark):
            await signals.wait()

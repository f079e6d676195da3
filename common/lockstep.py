"""Taking part in a lockstep run: count what is sent and received, report when quiet.

At ``--rate max`` a sim that only bounds how stale a decision may be (``--max-lag``) lets the
outcome depend on the scheduling of a dozen processes. In lockstep the sim steps only when
the whole stack is *quiet*: every message caused by what the sim published has been handled
and every command decided from it has reached the sim. The same world and seed then give the
same run on a quiet or a loaded machine (docs/SIM.md, "Lockstep"; CONTRACT.md, "Lockstep").

A participant (every process of the stack with PNAV_LOCKSTEP set; the sim is the judge):

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

How quiet is detected is the participant's business; the Engine and the bridge do it with
:meth:`Ledger.mark` / :meth:`Ledger.report_if_settled`: take a mark, make sure everything
received up to it is handled, then report if nothing was received since the mark.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any

import msgpack
import zenoh

from common.contract import keys

log = logging.getLogger("pnav.lockstep")


class Tally:
    """Receipts of one subscription, per key."""

    __slots__ = ("counts", "key_expr")

    def __init__(self, key_expr: str) -> None:
        self.key_expr = key_expr
        self.counts: dict[str, int] = {}


class Ledger:
    """One participant's counts and its status publisher (thread-safe)."""

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


_active: Ledger | None = None


def active() -> Ledger | None:
    """This process's ledger while it takes part in a lockstep run."""
    return _active


def start(session: zenoh.Session, service: str, instance: str, *, receipts: bool = True) -> Ledger:
    """Take part: from now on common.bus counts on the returned ledger. One per process."""
    global _active
    if _active is not None:
        raise RuntimeError("this process already takes part in a lockstep run")
    _active = Ledger(session, service, instance, receipts=receipts)
    return _active


def stop() -> None:
    global _active
    ledger, _active = _active, None
    if ledger is not None:
        ledger.close()

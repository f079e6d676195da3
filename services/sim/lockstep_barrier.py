"""Lockstep: the sim steps only when the whole stack is quiet (``--lockstep SERVICES``).

Pacing by the stack (``--max-lag``, lag_gate.py) bounds how stale a decision may be; between two
decisions the sim still runs on, so a run depends on the scheduling of a dozen processes.
In lockstep the sim publishes the clock (every 0.05 s of sim time), then each reading of a
step, one at a time, and after each waits until every participant (common.lockstep) reports
it handled everything that followed: the rows written, the engines' activations run, the
decisions made and the commands received here. The next physics step then starts from the
same state every run.

The check (:meth:`Barrier.quiet`): for every participant's every subscription and every key
it matches, the receipts it reported are at least what all participants and the sim
reported sent on that key; and the sim received every cmd_vel the bridge reported sent.
common/lockstep.py says why one look at the newest statuses is enough.

- **Start.** The sim holds at sim time 0 (its clock out at 0, the world answered) until
  every service named in ``expected`` has reported, and all are quiet: a benchmark runner
  taking part sets its mission first, so the run starts from the same state.
- **Lost.** Messages sent before a participant subscribed never reach it; neither does one
  lost on the way. A participant reports only when quiet, so one still lacking a message in
  a report LOST_AFTER_S after the report that first showed the lack never got it: it is
  not waited for again (``lost``). At start the sim nudges the stack with the clock every
  HOLD_NUDGE_S so that every participant reports and start-up misses show up.
- **Timeouts.** A wait ends after ``timeout_s`` of wall time anyway (``timeouts``): a
  participant that owes something and said nothing all that while is forgotten until it
  reports again (then it joins anew); what the others lack is counted lost (a dropped
  message) and not waited for again. The run goes on, but is no longer exactly
  repeatable; the sim logs it, and ``pnav bench nav`` reports it per run.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import zenoh

from common.bus import subscribe_threaded
from common.contract import keys
from common.lockstep import Status
from common.log import event

log = logging.getLogger(__name__)

DEFAULT_TIMEOUT_S = 5.0
# a participant still lacking a message in a report this long (wall) after the report that
# first showed the lack never got it
LOST_AFTER_S = 0.5
START_TIMEOUT_S = 120.0  # services start, a runner writes its mission
HOLD_NUDGE_S = 0.2  # at sim time 0, the clock goes out again this often (wall)
CMD_VEL_WATCH = keys.robot_watch(keys.CMD_VEL)
SIM = "sim"  # the sim's own receipts, as a participant


class _Participant:
    __slots__ = ("forgotten", "heard_at", "lacking_since", "offsets", "status")

    def __init__(self, status: Status, heard_at: float) -> None:
        self.status = status
        self.heard_at = heard_at
        # (subscription index, key) -> receipts not owed (negative: lost or before it came)
        self.offsets: dict[tuple[int, str], int] = {}
        # (subscription index, key) -> when a report of it first showed it lacking that key
        self.lacking_since: dict[tuple[int, str], float] = {}
        # silent through a timeout: not waited for until its next report (see _give_up)
        self.forgotten = False


class Barrier:
    def __init__(
        self,
        session: zenoh.Session,
        expected: tuple[str, ...],
        *,
        timeout_s: float = DEFAULT_TIMEOUT_S,
        start_timeout_s: float = START_TIMEOUT_S,
    ) -> None:
        self.expected = frozenset(expected)
        self.timeout_s = timeout_s
        self.start_timeout_s = start_timeout_s
        self.sent: dict[str, int] = {}  # the sim's own publications, per key
        self.cmd_received: dict[str, int] = {}
        self._own = _Participant(Status(0, {}, [(CMD_VEL_WATCH, self.cmd_received)]), 0.0)
        self._participants: dict[str, _Participant] = {}
        self._matches: dict[tuple[str, str], bool] = {}
        # every key ever sent, in the order first seen; per key expression, how many of
        # them it was tested against and those it matches (_matching)
        self._keys: list[str] = []
        self._keys_seen: set[str] = set()
        self._matched: dict[str, tuple[int, list[str]]] = {}
        self._cond = threading.Condition()
        self.waits = 0
        self.timeouts = 0
        self.lost = 0  # messages a participant never got in the run (see _check_lost)
        self.missed_at_start = 0  # the same in the hold: sent before it subscribed
        self.waited_wall_s = 0.0
        self.started = False
        self._subscriber = subscribe_threaded(session, keys.LOCKSTEP_WATCH, self._on_status)

    # -- what comes in (Zenoh's threads) and goes out (the sim's thread) ---------------------
    def _on_status(self, key: str, payload: bytes) -> None:
        try:
            status = Status.decode(payload)
            keys.parse_lockstep_key(key)
        except ValueError as exc:
            event(log, logging.WARNING, "bad lockstep status ignored", key=key, problem=str(exc))
            return
        with self._cond:
            known = self._participants.get(key)
            if known is None:
                known = self._participants[key] = _Participant(status, time.monotonic())
            elif status.seq > known.status.seq:
                known.status, known.heard_at = status, time.monotonic()
                known.forgotten = False
            else:
                return
            self._check_lost(known)
            self._cond.notify_all()

    def _check_lost(self, p: _Participant) -> None:
        """A participant reports only when quiet: if it still lacks a message in a report
        LOST_AFTER_S after the one that first showed the lack, the message never reached
        it (sent before it subscribed, or lost on the way) and is not waited for again."""
        now = p.heard_at
        lacks = {(index, key): short for index, key, short in self._lacking(p, self._totals())}
        for seen in [seen for seen in p.lacking_since if seen not in lacks]:
            del p.lacking_since[seen]
        for seen, short in lacks.items():
            since = p.lacking_since.setdefault(seen, now)
            if now - since >= LOST_AFTER_S:
                p.offsets[seen] = p.offsets.get(seen, 0) - short
                del p.lacking_since[seen]
                if self.started:
                    self.lost += short
                else:
                    self.missed_at_start += short

    def on_cmd_vel(self, key: str) -> None:
        """A cmd_vel on ``key`` reached the sim and was applied (any thread)."""
        with self._cond:
            self.cmd_received[key] = self.cmd_received.get(key, 0) + 1
            self._cond.notify_all()

    def published(self, key: str) -> None:
        """The sim is about to publish a counted message on ``key``."""
        with self._cond:
            self.sent[key] = self.sent.get(key, 0) + 1

    # -- the check (under the lock) ------------------------------------------------------------
    def _totals(self) -> dict[str, int]:
        totals = dict(self.sent)
        for p in self._participants.values():
            for key, n in p.status.sent.items():
                totals[key] = totals.get(key, 0) + n
        if len(totals) > len(self._keys_seen):
            self._keys.extend(key for key in totals if key not in self._keys_seen)
            self._keys_seen.update(totals)
        return totals

    def _matching(self, key_expr: str) -> list[str]:
        """Every key sent so far that ``key_expr`` matches. The check runs after every
        status, for every subscription of every participant: testing each sent key
        against each expression there was most of the sim's CPU in lockstep, so each
        expression keeps its list and tests only the keys that are new since."""
        known = self._matched.get(key_expr)
        if known is None:
            known = self._matched[key_expr] = (0, [])
        tested, matched = known
        if tested < len(self._keys):
            matched.extend(k for k in self._keys[tested:] if self._matches_key(key_expr, k))
            self._matched[key_expr] = (len(self._keys), matched)
        return matched

    def _matches_key(self, key_expr: str, key: str) -> bool:
        found = self._matches.get((key_expr, key))
        if found is None:
            found = zenoh.KeyExpr(key_expr).intersects(zenoh.KeyExpr(key))
            self._matches[(key_expr, key)] = found
        return found

    def _lacking(self, p: _Participant, totals: dict[str, int]) -> list[tuple[int, str, int]]:
        """(subscription, key, receipts short) of what ``p`` has not handled yet."""
        short: list[tuple[int, str, int]] = []
        for index, (key_expr, counts) in enumerate(p.status.subs):
            for key in self._matching(key_expr):
                n = totals.get(key, 0)
                got = counts.get(key, 0)
                offset = p.offsets.get((index, key), 0)
                if offset < 0 and got - offset > n:
                    # a late receipt of what was counted lost: owe it again
                    offset = p.offsets[(index, key)] = min(0, got - n)
                if got - offset < n:
                    short.append((index, key, n - (got - offset)))
        return short

    def _forgive(self, p: _Participant, totals: dict[str, int]) -> None:
        """What ``p`` lacks now is not owed: sent before it came, or lost."""
        for index, key, missing in self._lacking(p, totals):
            p.offsets[(index, key)] = p.offsets.get((index, key), 0) - missing

    def _everyone(self) -> list[_Participant]:
        return [self._own, *(p for p in self._participants.values() if not p.forgotten)]

    def present(self) -> bool:
        """Every expected service has reported at least once."""
        return self.expected <= self._services()

    def quiet(self) -> bool:
        """Nothing in flight anywhere (call with the lock held, or for a test's look)."""
        if not self.present():
            return False
        totals = self._totals()
        return not any(self._lacking(p, totals) for p in self._everyone())

    # -- waiting ----------------------------------------------------------------------------
    def wait(self, stop: threading.Event, *, within: float | None = None) -> bool:
        """Block until the stack is quiet (True), the timeout passed, or ``stop`` is set.
        With ``within``, give up after that many wall seconds instead, quietly: the caller
        nudges the stack and waits again (the hold at sim time 0)."""
        t0 = time.monotonic()
        deadline = t0 + (self.timeout_s if within is None else within)
        quiet = False
        with self._cond:
            self.waits += 1
            while not (quiet := self.quiet()):
                if stop.is_set():
                    break
                left = deadline - time.monotonic()
                if left <= 0:
                    if within is None:
                        self._give_up(t0)
                    break
                self._cond.wait(min(left, 0.1))
        self.waited_wall_s += time.monotonic() - t0
        return quiet

    def hold(self, stop: threading.Event, nudge: Callable[[], None]) -> bool:
        """At sim time 0: ``nudge()`` (publish the clock, counted) and wait, again and again,
        until every expected participant has reported and the stack is quiet. Each nudge
        makes every participant report, so what one never got (sent before it subscribed)
        shows as lost and is forgiven. False if ``start_timeout_s`` passed first."""
        deadline = time.monotonic() + self.start_timeout_s
        quiet = False
        while not stop.is_set() and not quiet:
            if time.monotonic() >= deadline:
                with self._cond:
                    self._give_up(deadline - self.start_timeout_s)
                break
            nudge()
            quiet = self.wait(stop, within=HOLD_NUDGE_S)
        with self._cond:
            # cmd_vel sent before the run (a stop at the bridge's start) is not owed
            self._forgive(self._own, self._totals())
            self.started = True
        return quiet

    def _give_up(self, since: float) -> None:
        """The wait that began at ``since`` timed out: a participant that owes something and
        said nothing all that while (stuck, gone, or it lost a message and had nothing else
        to report) is forgotten until it reports again; one that did report still lost a
        message: what it lacks is not waited for again."""
        self.timeouts += 1
        missing = sorted(self.expected - self._services())
        totals = self._totals()
        lagging = {
            k: short
            for k, p in self._participants.items()
            if not p.forgotten and (short := self._lacking(p, totals))
        }
        silent = [k for k in lagging if self._participants[k].heard_at < since]
        event(
            log,
            logging.WARNING,
            "lockstep wait timed out: the run is no longer exactly repeatable",
            missing=",".join(missing),
            silent=",".join(silent),
            lagging=";".join(
                f"{k}:{key}-{short}" for k, items in lagging.items() for _, key, short in items
            )[:500],
        )
        for key in silent:
            # what it owes now is forgiven with the rest: if it comes back, it owes only
            # what is sent from then on
            self._participants[key].forgotten = True
        for p in [self._own, *self._participants.values()]:
            self._forgive(p, totals)
        # the run goes on without those it never heard from
        self.expected = self.expected & self._services()

    def _services(self) -> set[str]:
        return {
            keys.parse_lockstep_key(k)[0] for k, p in self._participants.items() if not p.forgotten
        }

    def figures(self) -> dict[str, Any]:
        return {
            "lockstep_waits": self.waits,
            "lockstep_timeouts": self.timeouts,
            "lockstep_lost": self.lost,
            "lockstep_missed_at_start": self.missed_at_start,
            "lockstep_waited_wall_s": round(self.waited_wall_s, 3),
        }

    def close(self) -> None:
        try:
            self._subscriber.undeclare()
        except Exception:
            log.debug("undeclare failed", exc_info=True)

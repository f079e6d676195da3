"""Sim time as every service sees it: the newest ``pnav/sim/clock`` stamp, extrapolated.

The sim publishes its clock at about 20 Hz of wall time. Between two messages the clock is
extrapolated at the advertised rate, capped at 0.1 s of wall time, so expiry checks stay
smooth at ``--rate 10`` without running ahead of a sim that stalled. Older stamps are
ignored (reordering), unless more than a second older: that is a restarted sim.
"""

from __future__ import annotations

import logging
import time
from typing import TYPE_CHECKING, Any

import zenoh

from common import bus
from common.contract import keys

_MAX_EXTRAPOLATION_WALL_S = 0.1
# A clock this far behind the last one is a restarted sim, not a reordered message.
_RESTART_JUMP_S = 1.0

if TYPE_CHECKING:
    from common.lockstep import Ledger

log = logging.getLogger(__name__)


class SimClock:
    def __init__(self) -> None:
        self._stamp: float | None = None
        self._rate = 1.0
        self._received = 0.0
        self._subscriber: Any = None

    def attach(self, session: zenoh.Session, ledger: Ledger | None = None) -> None:
        """Follow ``pnav/sim/clock`` on ``session`` (callbacks on Zenoh's thread); in a
        lockstep run each clock message counts on ``ledger`` once the clock moved."""
        self._subscriber = bus.subscribe_threaded(
            session, keys.SIM_CLOCK, self._on_clock, ledger=ledger
        )

    def _on_clock(self, key: str, payload: bytes) -> None:
        try:
            body = bus.unpack(payload)
            stamp = float(body["stamp"])
            rate = float(body.get("rate", 1.0))
        except (ValueError, KeyError, TypeError):
            return
        # One tuple-free sequence of float stores: a reader may see the new stamp with the old
        # receive time for an instant, which errs towards the past, never the future.
        self.update(stamp, rate)

    def update(self, stamp: float, rate: float = 1.0) -> None:
        if self._stamp is not None and stamp < self._stamp:
            if self._stamp - stamp < _RESTART_JUMP_S:
                return  # a late, reordered message
            # Far back: the sim restarted. Follow it, or every sim-time rule (the bridge's
            # watchdog first) would stay frozen until the new run caught up.
            log.warning(
                "sim clock jumped back from %.3f to %.3f s: sim restarted", self._stamp, stamp
            )
        self._received = time.monotonic()
        self._rate = rate
        self._stamp = stamp

    @property
    def stamp(self) -> float | None:
        """The newest stamp heard, not extrapolated (None before the first): a held sim's
        clock (services/sim/hold.py) stands exactly at the time it holds at."""
        return self._stamp

    @property
    def started(self) -> bool:
        return self._stamp is not None

    def now(self) -> float:
        """Current sim time in seconds; 0.0 until the first clock message."""
        stamp = self._stamp
        if stamp is None:
            return 0.0
        if self._rate <= 0:
            return stamp
        elapsed = min(time.monotonic() - self._received, _MAX_EXTRAPOLATION_WALL_S)
        return stamp + max(elapsed, 0.0) * self._rate

    def now_if_started(self) -> float | None:
        """Sim time now, or None before the sim's clock was ever heard (a stamp left NULL
        rather than a made-up 0.0)."""
        return self.now() if self.started else None

    def close(self) -> None:
        if self._subscriber is not None:
            self._subscriber.undeclare()
            self._subscriber = None

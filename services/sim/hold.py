"""``--held``: the sim runs only as far as it is let, by ``pnav/sim/run`` messages.

A program that drives a mission on wall time against a sim at 5x (``pnav demo``) drives
another mission on a loaded machine: a driver that took 6 wall seconds to give its first
goal gave it at 33 s of sim time, with the battery drained meanwhile. Held, the sim starts
at sim time 0 and steps only up to the ``until`` of the newest ``pnav/sim/run`` message:
``{"until": S}`` runs it to sim time S (the first physics step at or after S) and holds it
there, ``{"until": null}`` lets it run on. A driver thus acts at the sim times it chose,
however slow the machine: a loaded machine makes the mission take longer in wall time, not
another mission.

While held the sim publishes its clock (rate 0: the stack does not extrapolate a time that
stands still), the world and the collision resends as when running; it does not step, so no
sensor reading, battery drain or command timeout happens. A message that is not a map with
``until`` nil or a finite number >= 0 is logged and ignored.
"""

from __future__ import annotations

import logging
import math
import threading

import zenoh

from common.bus import subscribe_threaded, unpack
from common.contract import keys
from common.log import event

log = logging.getLogger(__name__)


class Hold:
    def __init__(self, session: zenoh.Session) -> None:
        self._until: float | None = 0.0  # held at sim time 0 until told otherwise
        self._changed = threading.Condition()
        self._subscriber = subscribe_threaded(session, keys.SIM_RUN, self._on_run)

    def _on_run(self, key: str, payload: bytes) -> None:
        try:
            until = parse_until(unpack(payload))
        except (ValueError, KeyError, TypeError):
            event(log, logging.WARNING, "malformed pnav/sim/run ignored", payload=payload[:80])
            return
        with self._changed:
            self._until = until
            self._changed.notify_all()
        event(log, logging.INFO, "sim let run", until="on" if until is None else until)

    @property
    def until(self) -> float | None:
        """The sim time the sim may run to (None: on)."""
        return self._until

    def holding(self, sim_time: float) -> bool:
        """Whether the sim, at ``sim_time``, must not step."""
        until = self._until
        return until is not None and sim_time >= until - 1e-9

    def wait(self, timeout: float) -> None:
        """Sleep ``timeout`` seconds, or less when a run message comes."""
        with self._changed:
            self._changed.wait(timeout)

    def close(self) -> None:
        self._subscriber.undeclare()


def parse_until(body: object) -> float | None:
    """The ``until`` of a run message; ValueError, KeyError or TypeError if malformed."""
    if not isinstance(body, dict):
        raise TypeError("not a map")
    until = body["until"]
    if until is None:
        return None
    if isinstance(until, bool) or not isinstance(until, int | float):
        raise TypeError("until is not a number")
    if not (math.isfinite(until) and until >= 0):
        raise ValueError("until is not a finite sim time >= 0")
    return float(until)

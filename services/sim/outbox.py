"""Collision events kept until the bridge acknowledges them, resent meanwhile.

A sensor reading lost on the way is replaced by the next one; a collision event is not, and
the contract says it is never dropped. Zenoh's reliability ends at the router: an event put
while the router is frozen, or taken by a bridge that then failed to write it (Postgres
away), is gone. So the robot does what a ROS driver with a reliable event topic does: it
keeps each event, per robot, until ``pnav/robot/{robot}/collision_ack`` names it
(``{run, seq}``, sent by the bridge once the row is committed), and sends it again every
``resend_s`` of wall time meanwhile. The bridge writes one row per (robot, run, seq) however
often it comes (migration 7). ``run`` is new at every start of the sim, since ``seq`` then
starts again from 0.

At most ``limit`` events wait per robot; beyond that the oldest is given up (counted in
``given_up`` and logged): a robot in contact for minutes with no bridge at all must not grow
without bound. A sim killed loses what it held, as a rebooted robot would.

Thread-safe: events are added on the sim's thread, acks arrive on Zenoh's.
"""

from __future__ import annotations

import logging
import threading
import time
import uuid
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

from common.bus import unpack
from common.contract import keys
from common.log import event

log = logging.getLogger(__name__)

RESEND_S = 0.5
LIMIT = 256


def new_run() -> str:
    """A run id: unique enough that two runs of a sim never share one (12 hex digits)."""
    return uuid.uuid4().hex[:12]


class CollisionOutbox:
    def __init__(
        self,
        *,
        run: str | None = None,
        resend_s: float = RESEND_S,
        limit: int = LIMIT,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.run = run or new_run()
        self.resend_s = resend_s
        self.limit = limit
        self.clock = clock
        self._lock = threading.Lock()
        # robot -> seq -> (message, wall time it was last sent)
        self._held: dict[str, OrderedDict[int, tuple[dict[str, Any], float]]] = {}
        self.resent = 0
        self.acked = 0
        self.given_up = 0

    def sent(self, robot: str, message: dict[str, Any]) -> None:
        """``message`` (a collision event, with ``seq``) went out now: hold it until acked."""
        with self._lock:
            held = self._held.setdefault(robot, OrderedDict())
            held[message["seq"]] = (message, self.clock())
            while len(held) > self.limit:
                seq, _ = held.popitem(last=False)
                self.given_up += 1
                event(
                    log,
                    logging.WARNING,
                    "collision event given up: never acknowledged",
                    robot=robot,
                    seq=seq,
                    held=len(held),
                )

    def ack(self, robot: str, seq: int) -> bool:
        """The bridge committed event ``seq`` of ``robot``; False if it was not held."""
        with self._lock:
            held = self._held.get(robot)
            if held is None or held.pop(seq, None) is None:
                return False
            self.acked += 1
            return True

    def on_ack(self, key: str, payload: bytes) -> None:
        """A ``collision_ack`` message (Zenoh's thread); one for another run, or malformed,
        is ignored: it cannot name an event this run holds."""
        try:
            robot, _topic = keys.parse_robot_key(key)
            body = unpack(payload)
        except Exception:
            return
        if not isinstance(body, dict) or body.get("run") != self.run:
            return
        seq = body.get("seq")
        if isinstance(seq, int) and not isinstance(seq, bool):
            self.ack(robot, seq)

    def due(self) -> list[tuple[str, dict[str, Any]]]:
        """The events to send again now (each marked sent now), oldest first per robot."""
        now = self.clock()
        out: list[tuple[str, dict[str, Any]]] = []
        with self._lock:
            for robot, held in self._held.items():
                for seq, (message, at) in held.items():
                    if now - at >= self.resend_s:
                        held[seq] = (message, now)
                        out.append((robot, message))
        self.resent += len(out)
        return out

    def waiting(self) -> int:
        with self._lock:
            return sum(len(held) for held in self._held.values())

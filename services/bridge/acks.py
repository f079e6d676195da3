"""Collision events acknowledged once committed, so the robot stops resending them.

A collision event cannot be recomputed, so the robot keeps each one until the bridge
acknowledges it (CONTRACT.md, "Robot and sim"): one ``pnav/robot/{robot}/collision_ack``
message per event, ``{run, seq}``, sent after the row is committed (or was already there: a
resend), or after the database refused the row's values (resending the same values would
only be refused again). An event the bridge never wrote (Postgres away, the message
malformed, the robot not known yet) is not acknowledged: the robot sends it again later.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable

import zenoh

from common import bus, lockstep
from common.contract import keys
from services.bridge.counters import Counters, RateLimitedLog
from services.bridge.sensor_payloads import Collision, SensorRecord

logger = logging.getLogger("pnav.bridge.acks")


class CollisionAcks:
    def __init__(
        self, session: zenoh.Session, counters: Counters, ledger: lockstep.Ledger | None = None
    ) -> None:
        self.session = session
        self.counters = counters
        self.ledger = ledger
        self._alerts = RateLimitedLog(logger)

    def committed(self, records: Iterable[SensorRecord]) -> None:
        """``records`` are in their table (or refused for good): acknowledge the collisions."""
        for record in records:
            if isinstance(record, Collision):
                self._ack(record)

    def _ack(self, event: Collision) -> None:
        key = keys.robot_key(event.robot_id, keys.COLLISION_ACK)
        if self.ledger is not None:
            self.ledger.sent_on(key)
        try:
            # waits for room rather than be dropped: a lost ack only costs a resend, but
            # every resend is one more INSERT that finds its row already there
            self.session.put(
                key,
                bus.pack({"run": event.run, "seq": event.seq}),
                congestion_control=zenoh.CongestionControl.BLOCK,
            )
        except Exception as exc:  # Zenoh closing: the robot resends, the row is not doubled
            self._alerts.warning("ack", "collision ack failed", error=exc)
            return
        self.counters.collision_acks += 1

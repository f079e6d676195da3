"""The bridge's counters, and a logger that cannot be flooded.

Counters are plain integers touched only on the event loop's thread, so they need no lock.
Tests read them through :meth:`Counters.snapshot`; the bridge logs the same snapshot every
``stats_period_s``.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Hashable
from dataclasses import dataclass, field
from typing import Any

from common import log
from common.outage import is_connection_error


@dataclass
class Counters:
    messages_in: Counter[str] = field(default_factory=Counter)  # per sensor topic
    rows_written: Counter[str] = field(default_factory=Counter)  # per table
    batches: Counter[str] = field(default_factory=Counter)  # INSERT statements, per table
    largest_batch: Counter[str] = field(default_factory=Counter)  # rows, per table
    malformed: Counter[tuple[str, str]] = field(default_factory=Counter)  # (topic, reason)
    rejected_by_db: Counter[str] = field(default_factory=Counter)  # rows Postgres refused
    dropped: Counter[str] = field(default_factory=Counter)  # rows lost (db down, overflow)
    # rows a Postgres crash lost after their commit, written again (replay.py)
    rows_restored: Counter[str] = field(default_factory=Counter)
    rows_pruned: int = 0
    commands_out: int = 0
    commands_from_images: int = 0  # command2robot notifications sent on their image alone
    command_reads: int = 0  # queries of command2robot (start, notifications, period)
    # command2robot notifications that never arrived (a skip in their publisher's seq)
    command_notes_lost: int = 0
    # row images refused per table (broke the table's rules, common.images): read instead
    images_refused: Counter[str] = field(default_factory=Counter)
    watchdog_stops: int = 0
    shutdown_stops: int = 0
    # the safety layer: commands it stopped, slowed, or could not check (no fresh scan)
    safety_stopped: int = 0
    safety_limited: int = 0
    safety_unchecked: int = 0
    safety_zone_capped: int = 0  # of those, commands a speed zone capped (speed_zones.py)
    worlds_applied: int = 0
    worlds_unchanged: int = 0
    worlds_malformed: int = 0
    collision_acks: int = 0  # collision events acknowledged to the robot (acks.py)
    # ROS 2 scans' beams the contract has no value of, mapped per kind (ros2msgs.py)
    ros2_beams: Counter[str] = field(default_factory=Counter)

    def malformed_total(self, topic: str | None = None) -> int:
        return sum(n for (t, _), n in self.malformed.items() if topic is None or t == topic)

    def snapshot(self) -> dict[str, Any]:
        """A JSON-friendly copy; ``malformed`` keys are ``topic/reason``."""
        return {
            "messages_in": dict(self.messages_in),
            "rows_written": dict(self.rows_written),
            "batches": dict(self.batches),
            "largest_batch": dict(self.largest_batch),
            "malformed": {f"{t}/{r}": n for (t, r), n in sorted(self.malformed.items())},
            "rejected_by_db": dict(self.rejected_by_db),
            "dropped": dict(self.dropped),
            "rows_restored": dict(self.rows_restored),
            "rows_pruned": self.rows_pruned,
            "commands_out": self.commands_out,
            "commands_from_images": self.commands_from_images,
            "command_reads": self.command_reads,
            "command_notes_lost": self.command_notes_lost,
            "images_refused": dict(self.images_refused),
            "watchdog_stops": self.watchdog_stops,
            "shutdown_stops": self.shutdown_stops,
            "safety_stopped": self.safety_stopped,
            "safety_limited": self.safety_limited,
            "safety_unchecked": self.safety_unchecked,
            "safety_zone_capped": self.safety_zone_capped,
            "worlds_applied": self.worlds_applied,
            "worlds_unchanged": self.worlds_unchanged,
            "worlds_malformed": self.worlds_malformed,
            "collision_acks": self.collision_acks,
            "ros2_beams": dict(self.ros2_beams),
        }


class RateLimitedLog:
    """Logs an event at most once per ``period_s`` per key, then says how many it swallowed.

    The key must come from a small set (topic and reason, never a robot id taken from the
    wire), or the table of keys itself becomes the flood.

    An ``error`` field that is an exception is logged as its repr; when it says the database
    could not be reached, the record also carries it, so that while Postgres is down the
    process's outage (common/outage.py) folds the line into its periodic summary: one
    outage, a bounded handful of lines, whatever the number of tables and loops failing.
    """

    def __init__(self, logger: logging.Logger, period_s: float = 5.0) -> None:
        self.logger = logger
        self.period_s = period_s
        self._last: dict[Hashable, float] = {}
        self._suppressed: Counter[Hashable] = Counter()

    def log(self, level: int, key: Hashable, msg: str, /, **fields: Any) -> bool:
        """Log now unless ``key`` was logged less than ``period_s`` ago; True if logged."""
        now = time.monotonic()
        last = self._last.get(key)
        if last is not None and now - last < self.period_s:
            self._suppressed[key] += 1
            return False
        self._last[key] = now
        suppressed = self._suppressed.pop(key, 0)
        if suppressed:
            fields["suppressed"] = suppressed
        error = fields.get("error")
        if isinstance(error, BaseException):
            fields["error"] = repr(error)
            if is_connection_error(error):
                if self.logger.isEnabledFor(level):
                    self.logger.log(level, msg, extra=fields, exc_info=error)
                return True
        log.event(self.logger, level, msg, **fields)
        return True

    def warning(self, key: Hashable, msg: str, /, **fields: Any) -> bool:
        return self.log(logging.WARNING, key, msg, **fields)

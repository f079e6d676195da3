"""The sim's latency trace: when each sensor message left the sim and each command arrived.

Sense-to-act latency starts the moment the sim publishes a sensor message and ends the moment
the velocity command decided from it reaches the sim; only the sim can stamp both ends, so
with ``--trace FILE`` (``PNAV_SIM_TRACE``) it writes one CSV line per event:

    kind,robot,ref,wall_ns

``kind`` is a sensor topic (``scan``, ``odom``, ``battery``, ``collision``) with ``ref`` the
message's ``seq`` (the bridge stores it in the row's ``seq`` column), or ``cmd_vel`` with
``ref`` the ``command_id`` (a ``command2robot`` id; commands without one are not traced).
``wall_ns`` is ``time.time_ns()``: the same clock as Postgres' ``clock_timestamp()`` on the
same machine, so the stages in between can be placed on one time line.

Events are appended from the sim loop and Zenoh's threads (``deque.append`` is atomic) and
written by the loop every :data:`FLUSH_PERIOD_S`, so a reader sees the file grow while the
sim runs.
"""

from __future__ import annotations

import collections
import time
from pathlib import Path
from typing import IO, NamedTuple

FLUSH_PERIOD_S = 0.5
CMD_VEL = "cmd_vel"


class TraceEvent(NamedTuple):
    kind: str
    robot: str
    ref: int
    wall_ns: int


class Tracer:
    def __init__(self, path: Path) -> None:
        self.path = path
        self._pending: collections.deque[TraceEvent] = collections.deque()
        self._file: IO[str] | None = path.open("w", encoding="ascii")
        self._file.write("kind,robot,ref,wall_ns\n")
        self._next_flush = 0.0

    def record(self, kind: str, robot: str, ref: int) -> None:
        self._pending.append(TraceEvent(kind, robot, ref, time.time_ns()))

    def maybe_flush(self) -> None:
        now = time.monotonic()
        if now >= self._next_flush:
            self._next_flush = now + FLUSH_PERIOD_S
            self.flush()

    def flush(self) -> None:
        if self._file is None:
            return
        lines = []
        while self._pending:
            e = self._pending.popleft()
            lines.append(f"{e.kind},{e.robot},{e.ref},{e.wall_ns}\n")
        if lines:
            self._file.writelines(lines)
            self._file.flush()

    def close(self) -> None:
        self.flush()
        if self._file is not None:
            self._file.close()
            self._file = None


def read_trace(path: Path) -> list[TraceEvent]:
    """Every complete line of a trace file (a line being written is skipped)."""
    events = []
    with path.open(encoding="ascii") as f:
        next(f, None)
        for line in f:
            if not line.endswith("\n"):
                break
            kind, robot, ref, wall_ns = line.rstrip("\n").split(",")
            events.append(TraceEvent(kind, robot, int(ref), int(wall_ns)))
    return events

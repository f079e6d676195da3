"""The latency trace: when each sensor message left the robot and each command reached it.

Sense-to-act latency starts the moment the sim publishes a sensor message and ends the moment
the velocity command decided from it reaches the sim; only the sim can stamp both ends, so
with ``--trace FILE`` (``PNAV_SIM_TRACE``) it writes one CSV line per event:

    kind,robot,ref,wall_ns,wire

``kind`` is a sensor topic (``scan``, ``odom``, ``battery``, ``collision``) with ``ref`` the
message's ``seq``, or ``cmd_vel`` with ``ref`` the ``command_id`` (a ``command2robot`` id).
``wire`` is the robot link's own number for the message where it has one, else -1: on the
ROS 2 link, the rmw_zenoh attachment's sequence number of the publisher that sent it.

On the native link the bridge stores a reading's ``seq`` and sends the command id inside
cmd_vel, so the sim's trace alone joins a command to the reading it came from. A ROS 2
reading's row keeps the attachment's number instead (the ROS 2 messages have no ``seq``),
and a Twist carries no command id, so on the ROS 2 link three traces make the join: the sim
traces each reading with its attachment number as ``wire`` and each cmd_vel it applied by
its attachment number (``ref`` -1), and the bridge (``PNAV_BRIDGE_TRACE``) traces each
command it sent as ``cmd_vel`` with the command id as ``ref`` and the attachment number of
the robot's cmd_vel publisher as ``wire``.

``wall_ns`` is ``time.time_ns()``: the same clock as Postgres' ``clock_timestamp()`` on the
same machine, so the stages in between can be placed on one time line. Events are appended
from the writer's loop and Zenoh's threads (``deque.append`` is atomic) and written by the
owner every :data:`FLUSH_PERIOD_S`, so a reader sees the file grow while the run goes on.
"""

from __future__ import annotations

import collections
import time
from pathlib import Path
from typing import IO, NamedTuple

FLUSH_PERIOD_S = 0.5
CMD_VEL = "cmd_vel"
NO_REF = -1  # a ROS 2 cmd_vel at the sim: the command's id does not cross that wire
HEADER = "kind,robot,ref,wall_ns,wire\n"


class TraceEvent(NamedTuple):
    kind: str
    robot: str
    ref: int
    wall_ns: int
    wire: int = NO_REF


class Tracer:
    def __init__(self, path: Path) -> None:
        self.path = path
        self._pending: collections.deque[TraceEvent] = collections.deque()
        self._file: IO[str] | None = path.open("w", encoding="ascii")
        self._file.write(HEADER)
        self._next_flush = 0.0

    @staticmethod
    def now() -> int:
        """The trace's clock, for an event stamped before its ``wire`` number is known."""
        return time.time_ns()

    def record(
        self, kind: str, robot: str, ref: int, wire: int = NO_REF, wall_ns: int | None = None
    ) -> None:
        stamp = time.time_ns() if wall_ns is None else wall_ns
        self._pending.append(TraceEvent(kind, robot, ref, stamp, wire))

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
            lines.append(f"{e.kind},{e.robot},{e.ref},{e.wall_ns},{e.wire}\n")
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
            kind, robot, ref, wall_ns, wire = line.rstrip("\n").split(",")
            events.append(TraceEvent(kind, robot, int(ref), int(wall_ns), int(wire)))
    return events

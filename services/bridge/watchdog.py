"""The command watchdog, in sim time: no fresh command for ``timeout_s`` -> stop, once.

A fresh command is a new command2robot row. The TurtleBot3 firmware and ROS's
diff_drive_controller both stop a robot whose command stream went quiet for 0.5 s; we do the
same in *sim* time, so a mission run at ``--rate 10`` times out after 0.05 s of wall time and
a paused sim never trips it.

Pure bookkeeping, no I/O: :class:`~services.bridge.command_relay.CommandRelay` feeds it and sends
the stops it returns.
"""

from __future__ import annotations


class Watchdog:
    def __init__(self, timeout_s: float) -> None:
        self.timeout_s = timeout_s
        # robot -> sim time of its newest fresh command; None if it came before the sim
        # clock started (the first clock reading then stands in for it)
        self._fed: dict[str, float | None] = {}

    def feed(self, robot: str, now: float | None) -> None:
        """A fresh command for ``robot`` arrived at sim time ``now`` (None: no clock yet)."""
        self._fed[robot] = now

    def expired(self, now: float) -> list[tuple[str, float]]:
        """Robots whose last fresh command is ``timeout_s`` old at ``now``, with its age.

        Each trips once: it is disarmed until :meth:`feed` arms it again.
        """
        tripped: list[tuple[str, float]] = []
        for robot, fed in list(self._fed.items()):
            if fed is None or now < fed:
                # no clock when it was fed, or the sim restarted and time went back:
                # start counting from now rather than from a time on another clock
                self._fed[robot] = now
            elif now - fed >= self.timeout_s:
                del self._fed[robot]
                tripped.append((robot, now - fed))
        return tripped

    def disarm(self, robot: str) -> None:
        self._fed.pop(robot, None)

    def armed(self) -> set[str]:
        return set(self._fed)

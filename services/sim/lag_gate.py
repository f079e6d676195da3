"""Pacing by the stack: the sim never runs more than ``max_lag`` sim seconds past a decision.

At ``--rate max`` the sim alone would run 200 times faster than real time and the services,
reacting in wall-clock milliseconds, would steer robots through seconds of sim time on stale
commands: the outcome would depend on how loaded the machine is. With ``--max-lag S`` the
sim waits, before each physics step, until every robot under command has a decision no
older than ``S`` sim seconds (``decided_stamp`` of its newest ``cmd_vel``, the decision's
sim time). The services then always react within ``S`` sim seconds, however slow the
machine: a loaded machine only makes the run take longer in wall time.

A robot is under command while its newest decision is at most ``hold_s`` old; a robot the
decision service stopped commanding (nothing live for it) is not waited for. A wait ends
after ``timeout_s`` of wall time anyway (counted in ``timeouts``) so a dead service cannot
freeze the sim; the bridge's watchdog then stops the robot, as in real time.

Until the first decision for any robot the node runs the sim at real time (``heard``
false): the services are still starting, and a sim racing ahead meanwhile would only flood
them with sensor messages they cannot use yet.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

DEFAULT_HOLD_S = 1.0
DEFAULT_TIMEOUT_S = 2.0
HEARTBEAT_S = 0.05  # the clock goes out this often (wall) while the sim waits: 20 Hz


class Gate:
    def __init__(
        self,
        max_lag_s: float,
        *,
        hold_s: float = DEFAULT_HOLD_S,
        timeout_s: float = DEFAULT_TIMEOUT_S,
    ) -> None:
        if not max_lag_s > 0:
            raise ValueError(f"max lag must be positive, got {max_lag_s}")
        self.max_lag_s = max_lag_s
        self.hold_s = max(hold_s, max_lag_s)
        self.timeout_s = timeout_s
        self._decided: dict[str, float] = {}
        self.heard = False  # a decision for some robot reached the sim
        self._cond = threading.Condition()
        self.waits = 0
        self.timeouts = 0
        self.waited_wall_s = 0.0

    def on_decision(self, robot: str, decided_stamp: float) -> None:
        """A command decided at sim time ``decided_stamp`` reached the sim (any thread)."""
        with self._cond:
            self.heard = True
            if decided_stamp > self._decided.get(robot, float("-inf")):
                self._decided[robot] = decided_stamp
                self._cond.notify_all()

    def behind(self, sim_time: float) -> list[str]:
        """Robots under command whose newest decision is older than ``max_lag_s``."""
        return [
            robot
            for robot, d in self._decided.items()
            if self.max_lag_s < sim_time - d <= self.hold_s
        ]

    def wait(self, sim_time: float, stop: threading.Event, heartbeat: Callable[[], None]) -> None:
        """Block until no robot is behind at ``sim_time`` (or the timeout, or ``stop``).
        ``heartbeat`` runs first and every HEARTBEAT_S of wall time while waiting: the node
        publishes its clock there, so services (even those that start meanwhile) see the
        time they must decide at."""
        with self._cond:
            if not self.behind(sim_time):
                return
        heartbeat()
        self.waits += 1
        t0 = time.monotonic()
        deadline = t0 + self.timeout_s
        next_beat = t0 + HEARTBEAT_S
        with self._cond:
            while self.behind(sim_time) and not stop.is_set():
                left = deadline - time.monotonic()
                if left <= 0:
                    self.timeouts += 1
                    # let the robots that are behind go: they are not waited for again
                    # until a fresh decision puts them back under command
                    for robot in self.behind(sim_time):
                        self._decided[robot] = sim_time - self.hold_s - 1.0
                    break
                self._cond.wait(min(left, HEARTBEAT_S))
                if time.monotonic() >= next_beat:
                    next_beat = time.monotonic() + HEARTBEAT_S
                    self._cond.release()  # publishing must not hold up on_decision
                    try:
                        heartbeat()
                    finally:
                        self._cond.acquire()
        self.waited_wall_s += time.monotonic() - t0

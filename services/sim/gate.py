"""Pacing by the stack: the sim never runs more than ``max_lag`` sim seconds past a decision.

At ``--rate max`` the sim alone would run 200 times faster than real time and the services,
reacting in wall-clock milliseconds, would steer robots through seconds of sim time on stale
commands: the outcome would depend on how loaded the machine is. With ``--max-lag S`` the
sim waits, before each physics step, until every robot under command has a decision no
older than ``S`` sim seconds (``decided_stamp`` of its newest ``cmd_vel``, the decision's
sim time). The services then always react within ``S`` sim seconds, however slow the
machine: a loaded machine only makes the run take longer in wall time.

A robot is under command while its newest decision is at most ``hold_s`` old; a robot the
decision service stopped commanding (nothing live for it) is not waited for. Every robot
starts under command, as if decided at sim time 0: the sim holds at ``max_lag`` until the
stack has started and decided for it (or ``first_timeout_s`` of wall time passed), so a
benchmark's robot does not idle through sim seconds while the services start. Any other
wait ends after ``timeout_s`` of wall time (counted in ``timeouts``) so a dead service cannot
freeze the sim; the bridge's watchdog then stops the robot, as in real time.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable

DEFAULT_HOLD_S = 1.0
DEFAULT_TIMEOUT_S = 2.0
DEFAULT_FIRST_TIMEOUT_S = 30.0


class Gate:
    def __init__(
        self,
        max_lag_s: float,
        robots: Iterable[str] = (),
        *,
        hold_s: float = DEFAULT_HOLD_S,
        timeout_s: float = DEFAULT_TIMEOUT_S,
        first_timeout_s: float = DEFAULT_FIRST_TIMEOUT_S,
    ) -> None:
        if not max_lag_s > 0:
            raise ValueError(f"max lag must be positive, got {max_lag_s}")
        self.max_lag_s = max_lag_s
        self.hold_s = max(hold_s, max_lag_s)
        self.timeout_s = timeout_s
        self.first_timeout_s = first_timeout_s
        self._decided: dict[str, float] = dict.fromkeys(robots, 0.0)
        self._heard: set[str] = set()  # robots with a real decision
        self._cond = threading.Condition()
        self.waits = 0
        self.timeouts = 0
        self.waited_wall_s = 0.0

    def on_decision(self, robot: str, decided_stamp: float) -> None:
        """A command decided at sim time ``decided_stamp`` reached the sim (any thread)."""
        with self._cond:
            self._heard.add(robot)
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

    def wait(self, sim_time: float, stop: threading.Event, before: Callable[[], None]) -> None:
        """Block until no robot is behind at ``sim_time`` (or the timeout, or ``stop``).
        ``before`` runs once first: the node publishes its clock there, so the services see
        the time they must decide at."""
        with self._cond:
            behind = self.behind(sim_time)
            if not behind:
                return
            first = any(robot not in self._heard for robot in behind)
        before()
        self.waits += 1
        t0 = time.monotonic()
        deadline = t0 + (self.first_timeout_s if first else self.timeout_s)
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
                self._cond.wait(min(left, 0.05))
        self.waited_wall_s += time.monotonic() - t0

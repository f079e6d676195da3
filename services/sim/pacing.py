"""Sim time: the fixed physics step, sensor schedules on sim time, and wall-clock pacing.

Sensors fire on *sim* time, counted in whole physics steps, never on wall time: running at
``--rate 10`` or ``--rate max`` changes how fast sim time passes, not what a robot senses per
sim second.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import KW_ONLY, dataclass, field

from common.errors import ConfigError

MAX = 0.0  # the rate value meaning "as fast as possible" (the contract's clock rate 0)


def parse_rate(value: str | float) -> float:
    """``"max"`` -> 0.0 (as fast as possible); ``"10"`` -> 10.0 sim seconds per wall second."""
    if isinstance(value, str):
        text = value.strip().lower()
        if text in ("max", "0", "inf", "fast"):
            return MAX
        try:
            rate = float(text)
        except ValueError:
            raise ConfigError(f"rate {value!r} must be a positive number or 'max'") from None
    else:
        rate = float(value)
    if not math.isfinite(rate) or rate < 0:
        raise ConfigError(f"rate {value!r} must be a positive number or 'max'")
    return rate


class Every:
    """Fires once per ``period_s`` of sim time, at the first step at or after each due time,
    starting with step 0; the long-run rate is exact even if the period is not a whole number
    of steps."""

    def __init__(self, period_s: float, dt: float, phase: float = 0.0) -> None:
        if period_s <= 0:
            raise ConfigError(f"a sensor period must be positive, got {period_s}")
        self.period_steps = period_s / dt
        # phase in [0, 1): the first firing is that fraction of a period after step 0
        self._next = float(round(phase * self.period_steps))

    def due(self, step: int) -> bool:
        # the tolerance absorbs float error in period/dt (0.2 / (1/240) = 48.000000001)
        if step + 1e-6 >= self._next:
            self._next += self.period_steps
            if self._next <= step:  # never owe a burst after a skipped stretch
                self._next = step + self.period_steps
            return True
        return False


@dataclass(eq=False)
class Pacer:
    """How many physics steps to run now so sim time follows ``rate`` x wall time.

    If the sim falls more than ``max_lag_s`` of wall time behind (the machine is too slow for
    the rate asked), it drops the debt instead of running a burst, and counts the slip.
    """

    rate: float
    dt: float
    _: KW_ONLY
    max_lag_s: float = 0.25
    wall: Callable[[], float] = time.monotonic
    slips: int = field(default=0, init=False)
    # the wall time and step count sim time is paced from (moved on by a slip)
    _anchor_wall: float = field(init=False, repr=False)
    _anchor_steps: int = field(default=0, init=False, repr=False)

    def __post_init__(self) -> None:
        self._anchor_wall = self.wall()

    def steps_due(self, steps_done: int) -> int:
        """Steps owed now (for ``--rate max``: a large batch, the caller checks the time)."""
        if self.rate == MAX:
            return 1 << 30
        elapsed = self.wall() - self._anchor_wall
        target = self._anchor_steps + int(elapsed * self.rate / self.dt + 1e-9)
        owed = target - steps_done
        if owed * self.dt > self.max_lag_s * self.rate:
            self.slips += 1
            self._anchor_wall = self.wall()
            self._anchor_steps = steps_done
            return 1
        return max(0, owed)

    def restart(self, steps_done: int) -> None:
        """Pace from now and ``steps_done`` on: time the sim stood still (held) is owed no
        steps, and is no slip."""
        self._anchor_wall = self.wall()
        self._anchor_steps = steps_done

    def wall_until_next(self, steps_done: int) -> float:
        """Wall seconds until the next step is due (0 for max rate)."""
        if self.rate == MAX:
            return 0.0
        due = self._anchor_wall + (steps_done + 1 - self._anchor_steps) * self.dt / self.rate
        return max(0.0, due - self.wall())

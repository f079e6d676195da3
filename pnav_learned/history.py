"""What foresight sees: the last seconds of one robot's rows, as numbers. One definition for
the dataset that trains its model (``pnav learn dataset`` adds these columns) and the
scenario that runs it, so the two can never disagree.

A :class:`History` holds one robot's samples (one per decision in the dataset, one per scan
in the scenario: the features are over time, not over samples, so the two rates agree) for
``WINDOW_S`` of sim time. Beside a decision's own features (pnav_learned.features) it gives:

- ``history_s``: how much of the window the samples cover (a fresh start has little);
- ``moved_1s``, ``moved_3s``: straight-line distance from the pose 1 s and 3 s ago, m;
- ``progress_3s``: how much nearer the path's end the robot came in the last 3 s, m;
- ``turned_3s``: the heading change over the last 3 s, summed in absolute value, rad;
- ``speed_mean_3s``: the mean absolute odometry speed over the window, m/s;
- ``ahead_min_3s``: the nearest hit ahead (the two sectors either side of straight ahead)
  over the window, m.

A new target (the path's end moved by more than ``NEW_TARGET_M``) or time going back (a new
run) starts the history afresh. The label foresight is trained to predict is ``no_progress``:
the robot comes less than ``NO_PROGRESS_M`` nearer the path's end in the next 3 s
(``progress_m`` of the dataset, horizon 3 s).
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from pnav_learned.features import FEATURES, SECTORS, FloatArray

WINDOW_S = 3.0
NEW_TARGET_M = 0.5
NO_PROGRESS_M = 0.3  # the planner's recovery_progress_m default: "no progress" there too
NEAR_TARGET_M = 1.0  # nearer than this the robot slows to arrive: not a lack of progress
AHEAD = (SECTORS // 2 - 1, SECTORS // 2)  # the sectors either side of straight ahead

HISTORY_FEATURES: tuple[str, ...] = (
    "history_s",
    "moved_1s",
    "moved_3s",
    "progress_3s",
    "turned_3s",
    "speed_mean_3s",
    "ahead_min_3s",
)
FORESIGHT_FEATURES: tuple[str, ...] = (*FEATURES, *HISTORY_FEATURES)
TARGET_DIST = FEATURES.index("target_dist")


@dataclass(frozen=True)
class Sample:
    stamp: float
    x: float
    y: float
    yaw: float
    speed: float  # odometry's linear speed, m/s
    target: tuple[float, float]  # the path's end, world frame
    target_dist: float
    ahead_m: float


def sample(
    stamp: float,
    pose: tuple[float, float, float],
    speed: float,
    target: tuple[float, float],
    decision: FloatArray,
) -> Sample:
    """A sample from one decision's features (pnav_learned.features.features)."""
    ahead = float(min(decision[i] for i in AHEAD))
    return Sample(stamp, *pose, speed, target, float(decision[TARGET_DIST]), ahead)


class History:
    """One robot's last ``WINDOW_S`` seconds of samples."""

    def __init__(self) -> None:
        self.samples: deque[Sample] = deque()

    def add(self, s: Sample) -> None:
        last = self.samples[-1] if self.samples else None
        if last is not None and (
            s.stamp < last.stamp or math.dist(s.target, last.target) > NEW_TARGET_M
        ):
            self.samples.clear()
        self.samples.append(s)
        # keep one sample at or before the window's start: the pose "3 s ago"
        while len(self.samples) >= 2 and self.samples[1].stamp <= s.stamp - WINDOW_S:
            self.samples.popleft()

    def _at(self, stamp: float) -> Sample:
        """The newest sample at or before ``stamp``, else the oldest."""
        found = self.samples[0]
        for s in self.samples:
            if s.stamp > stamp:
                break
            found = s
        return found

    def features(self) -> FloatArray:
        """The HISTORY_FEATURES as of the newest sample (zeros with no sample)."""
        if not self.samples:
            return np.zeros(len(HISTORY_FEATURES))
        now = self.samples[-1]
        one, three = self._at(now.stamp - 1.0), self._at(now.stamp - WINDOW_S)
        window = [s for s in self.samples if s.stamp >= now.stamp - WINDOW_S] or [now]
        turned = sum(
            abs(math.remainder(b.yaw - a.yaw, math.tau)) for a, b in itertools.pairwise(window)
        )
        return np.array(
            [
                min(now.stamp - self.samples[0].stamp, WINDOW_S),
                math.hypot(now.x - one.x, now.y - one.y),
                math.hypot(now.x - three.x, now.y - three.y),
                three.target_dist - now.target_dist,
                turned,
                float(np.mean([abs(s.speed) for s in window])),
                min(s.ahead_m for s in window),
            ]
        )


def no_progress(progress_m: float) -> bool:
    """The label: less than NO_PROGRESS_M nearer the target over the horizon."""
    return progress_m < NO_PROGRESS_M

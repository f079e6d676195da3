"""A laser scan's geometry, once for every reader: its beams' angles, and which beams carry a
reading.

The bridge's safety layer, the controller's sectors and the contract's LaserScan record all
ask the same two things of a scan; they ask them here, so they cannot disagree at a beam.
"""

from __future__ import annotations

import functools
from typing import Any, Final

import numpy as np
import numpy.typing as npt

# Below range_min a beam carries no information (ROS); inf is "nothing within range_max".
# Ranges are float32 (the real[] column): a hit at exactly range_min, the sim's reading for
# anything closer, must not be lost to rounding against the float64 range_min.
RANGE_TOLERANCE_M: Final = 1e-4


@functools.lru_cache(maxsize=16)
def beam_angles(
    angle_min: float, increment: float, n: int
) -> np.ndarray[Any, np.dtype[np.float64]]:
    """The ``n`` beams' angles relative to the heading, wrapped to (-pi, pi] (read-only:
    every scan of a lidar has the same geometry, so they are worked out once, not per scan)."""
    raw = angle_min + increment * np.arange(n)
    out = np.asarray(np.arctan2(np.sin(raw), np.cos(raw)), dtype=np.float64)
    out.flags.writeable = False
    return out


def readings(ranges: npt.NDArray[Any], range_min: float) -> npt.NDArray[np.bool_]:
    """Which beams carry a reading: at or beyond ``range_min`` (NaN never does; inf does,
    as "nothing within range_max")."""
    return np.asarray(ranges >= range_min - RANGE_TOLERANCE_M)

"""What bounds one dwa decision's work, whatever the strategy row, the scan and the path say
(a row may say anything): the nearest MAX_OBSTACLES merged hits are kept (more than the
shipped lidars' 720 beams), a pose x obstacle (or trajectory x path segment) product holds
at most PAIRS_PER_PRODUCT pairs at a time (256 KB of float32), and a path is scored and
tested against the lidar at most MAX_PATH_POINTS points along it. The poses are
params.POSE_BUDGET's (docs/CONTROLLER.md, *dwa*, "Bounded work").
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

MAX_OBSTACLES = 1024
PAIRS_PER_PRODUCT = 1 << 16
MAX_PATH_POINTS = 1000


def nearest(points: FloatArray, most: int) -> FloatArray:
    """The ``most`` points nearest the origin, in their order (all of them if fewer)."""
    if len(points) <= most:
        return points
    keep = np.argpartition(np.hypot(points[:, 0], points[:, 1]), most - 1)[:most]
    kept: FloatArray = points[np.sort(keep)]
    return kept


def thin(points: FloatArray, most: int) -> FloatArray:
    """At most ``most`` of ``points``, evenly spread, the first and the last kept (a path of
    a point every few millimetres tells no more than one every few centimetres)."""
    if len(points) <= most:
        return points
    thinned: FloatArray = points[np.linspace(0, len(points) - 1, most).astype(np.int64)]
    return thinned

"""Helpers for the navbench tests: an independent check that a path keeps the robot clear."""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt


def min_clearance(
    occupied: npt.NDArray[np.bool_],
    resolution: float,
    points: Sequence[tuple[float, float]],
    step_m: float = 0.01,
) -> float:
    """Smallest distance from any point of the polyline (sampled every ``step_m``) to any
    occupied cell's square, by brute force over the obstacles' rim cells; origin at (0, 0).
    Kept apart from the code under test so that a bug there cannot hide here. (A path from
    a free start that enters an obstacle crosses its rim, and reads about 0 there.)"""
    samples = []
    for (x0, y0), (x1, y1) in itertools.pairwise(points):
        n = max(2, int(np.hypot(x1 - x0, y1 - y0) / step_m) + 2)
        t = np.linspace(0.0, 1.0, n)
        samples.append(np.column_stack((x0 + t * (x1 - x0), y0 + t * (y1 - y0))))
    pts = np.concatenate(samples)
    # only cells on an obstacle's rim can be nearest to a point outside the obstacles
    padded = np.pad(occupied, 1, constant_values=True)
    inner = padded[:-2, 1:-1] & padded[2:, 1:-1] & padded[1:-1, :-2] & padded[1:-1, 2:]
    rows, cols = np.nonzero(occupied & ~inner)
    lo_x, lo_y = cols * resolution, rows * resolution
    best = np.inf
    for chunk in np.array_split(pts, max(1, len(pts) // 200)):
        dx = np.clip(chunk[:, :1], lo_x, lo_x + resolution) - chunk[:, :1]
        dy = np.clip(chunk[:, 1:], lo_y, lo_y + resolution) - chunk[:, 1:]
        best = min(best, float(np.sqrt(dx * dx + dy * dy).min()))
    return best

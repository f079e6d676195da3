"""dwa's lattice as a classifier's classes: learned_drive's model can pick among the
velocities dwa itself would sample rather than regress one (docs/LEARNING.md, *A classifier
over dwa's lattice*).

The lattice is the grid of dwa's default ``dwa_linear_samples`` x ``dwa_angular_samples``
(9 x 17) spread over the dynamic window of the decision (pnav_learned.candidates.bounds:
the odometry, the robot row's limits and accelerations, dwa's speed cap near the path's end
and before what is straight ahead). Class ``cell_i_j`` is the i-th speed (slowest first) and
the j-th turn rate (most clockwise first) of that window: a class is a place in the window,
not a fixed velocity, so the same label means "brake a little and turn left hard" at any
speed. dwa's choice for a recorded state is labelled with the cell nearest it, in cells
(:func:`nearest`); the window's extra turn rates (the one facing the carrot) and two-segment
arcs have no cell of their own, and take the nearest.
"""

from __future__ import annotations

import numpy as np

from pnav_local.dwa_params import DwaParams

FloatArray = np.ndarray[tuple[int, ...], np.dtype[np.float64]]

LINEAR = DwaParams().linear_samples
ANGULAR = DwaParams().angular_samples
CELLS: tuple[str, ...] = tuple(f"cell_{i}_{j}" for i in range(LINEAR) for j in range(ANGULAR))


# each cell's place in the window, 0 (slowest, most clockwise) to 1, in the order of CELLS
_AT_V = np.repeat(np.linspace(0.0, 1.0, LINEAR), ANGULAR)
_AT_W = np.tile(np.linspace(0.0, 1.0, ANGULAR), LINEAR)


def grid(window: tuple[float, float, float, float]) -> tuple[FloatArray, FloatArray]:
    """Every cell's (linear, angular) for the window (v_low, v_high, w_low, w_high), in the
    order of CELLS (a window with no room for speed repeats its one speed)."""
    v_low, v_high, w_low, w_high = window
    return v_low + (v_high - v_low) * _AT_V, w_low + (w_high - w_low) * _AT_W


def steps(window: tuple[float, float, float, float]) -> tuple[float, float]:
    """One cell's size in speed and in turn rate (never 0: a distance is divided by it)."""
    v_low, v_high, w_low, w_high = window
    return (
        max((v_high - v_low) / max(1, LINEAR - 1), 1e-3),
        max((w_high - w_low) / max(1, ANGULAR - 1), 1e-3),
    )


def nearest(velocity: tuple[float, float], window: tuple[float, float, float, float]) -> int:
    """The index in CELLS of the cell nearest ``velocity``, distance counted in cells."""
    v, w = grid(window)
    dv, dw = steps(window)
    return int(np.argmin(np.hypot((v - velocity[0]) / dv, (w - velocity[1]) / dw)))

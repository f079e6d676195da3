"""The cellular automaton that draws the obstacle field, as in BARN (Perille et al. 2020).

A grid of square cells is filled at random, each cell occupied with probability ``p``; then
``k`` smoothing steps update every cell at once from its 8 neighbours: a cell with at least
``fill_threshold`` occupied neighbours becomes occupied, one with at most ``clear_threshold``
becomes free, any other keeps its state. Few smoothing steps leave scattered clutter; more
steps grow it into blobs with open space between them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

BoolGrid = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class AutomatonRule:
    """The parameters of one cellular automaton (one difficulty level)."""

    fill_probability: float  # chance that a cell starts occupied
    smoothing_iterations: int
    fill_threshold: int = 5  # >= this many occupied neighbours: the cell fills
    clear_threshold: int = 1  # <= this many: the cell clears

    def __post_init__(self) -> None:
        if not 0.0 <= self.fill_probability <= 1.0:
            raise ValueError(f"fill_probability must be within [0, 1], got {self.fill_probability}")
        if self.smoothing_iterations < 0:
            raise ValueError("smoothing_iterations must not be negative")
        if not 0 <= self.clear_threshold < self.fill_threshold <= 8:
            raise ValueError("need 0 <= clear_threshold < fill_threshold <= 8")


def neighbour_counts(field: BoolGrid, *, sides_occupied: bool = True) -> npt.NDArray[np.int8]:
    """How many of each cell's 8 neighbours are occupied.

    Outside the field, the left and right sides count as occupied when ``sides_occupied``
    (they are the side walls, so obstacles cling to them as to the walls of a cave) and the
    bottom and top as free (they are the open start and goal zones).
    """
    padded = np.zeros((field.shape[0] + 2, field.shape[1] + 2), dtype=np.int8)
    padded[1:-1, 1:-1] = field
    if sides_occupied:
        padded[:, 0] = 1
        padded[:, -1] = 1
    rows, cols = field.shape
    counts = np.zeros(field.shape, dtype=np.int8)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if dr or dc:
                counts += padded[1 + dr : 1 + dr + rows, 1 + dc : 1 + dc + cols]
    return counts


def smooth(field: BoolGrid, rule: AutomatonRule) -> BoolGrid:
    """One synchronous smoothing step: every cell looks at the previous generation."""
    counts = neighbour_counts(field)
    out = field.copy()
    out[counts >= rule.fill_threshold] = True
    out[counts <= rule.clear_threshold] = False
    return out


def grow_field(rng: np.random.Generator, rows: int, cols: int, rule: AutomatonRule) -> BoolGrid:
    """A random fill of ``rows`` x ``cols`` cells, smoothed ``rule.smoothing_iterations`` times
    (row 0 at the bottom, next to the start zone)."""
    field: BoolGrid = rng.random((rows, cols)) < rule.fill_probability
    for _ in range(rule.smoothing_iterations):
        field = smooth(field, rule)
    return field

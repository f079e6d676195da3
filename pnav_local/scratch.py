"""Scratch arrays reused from one decision to the next: the pose x hit pairs' arithmetic
(clearance.py) works in them instead of fresh arrays.

A box's decision measures some 30,000 pairs, a quarter of a megabyte per array of them:
allocated fresh, such an array is mapped from the system and its pages faulted in on first
write, which cost several times the arithmetic written into it (the Jackal's box in BARN
clutter: 0.4 of its 2.0 ms were page faults, `python -m pnav.bench.dwa_decision`). Kept
per thread (each of a controller's threads its own), grown as needed; what they hold is
only valid until the next call that asks for the same name.
"""

from __future__ import annotations

import threading

import numpy as np
import numpy.typing as npt

_local = threading.local()


def array(name: str, size: int) -> npt.NDArray[np.float64]:
    """A float64 scratch array of ``size`` elements (contents undefined), this thread's
    ``name``."""
    held: dict[str, npt.NDArray[np.float64]] | None = getattr(_local, "held", None)
    if held is None:
        held = _local.held = {}
    buf = held.get(name)
    if buf is None or len(buf) < size:
        buf = held[name] = np.empty(max(size, 2 * (0 if buf is None else len(buf))))
    return buf[:size]


def arange(size: int) -> npt.NDArray[np.int64]:
    """0, 1, ..., size - 1 (read only: shared by every caller of this thread)."""
    held = getattr(_local, "arange", None)
    if held is None or len(held) < size:
        held = _local.arange = np.arange(max(size, 2 * (0 if held is None else len(held))))
        held.flags.writeable = False
    out: npt.NDArray[np.int64] = held[:size]
    return out

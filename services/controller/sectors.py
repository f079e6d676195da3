"""Geometry on one laser scan: the closest obstacle in a sector, how open a sector is, and
what the robot's round body would sweep driving forward or backward. Pure numpy, no I/O.

Angles are radians relative to the robot's heading, counter-clockwise, in (-pi, pi] (the
contract's laser_scan convention); a sector is ``(low, high)`` with ``low <= high`` and may
cross +-pi (it is matched by its centre and half-width, wrapped).

A lidar whose field of view is less than a full turn (the Jackal's 270 degrees) has no beams
behind it: a sector there is *unseen*, not clear. :meth:`ScanView.sees` says whether a sector
has beams; :meth:`ScanView.openness` of an unseen sector is 0 and :meth:`ScanView.left_is_freer`
never prefers an unseen side to a seen one, so no scenario steers into what it cannot see;
:meth:`ScanView.closest` of an unseen sector finds nothing, and a scenario that would act on
"nothing there" asks :meth:`ScanView.sees` first (safety_stop does, backing up).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from common.contract.records import LaserScan
from common.scan import readings

FloatArray = npt.NDArray[np.float64]
Sector = tuple[float, float]

# Two clearances closer than this are a tie: the lidar's noise (sigma 0.01 m) must not flip
# the turn direction from one scan to the next in front of a symmetric obstacle.
TIE_M = 0.03
_OPENNESS_TIE_M = 0.02


def deg(value: float) -> float:
    return math.radians(value)


@dataclass(frozen=True)
class Hit:
    """The closest beam of a query: its range (inf when nothing) and angle."""

    range_m: float
    angle_rad: float

    @property
    def found(self) -> bool:
        return math.isfinite(self.range_m)

    @property
    def angle_deg(self) -> float:
        return math.degrees(self.angle_rad)

    def describe(self) -> str:
        return f"{self.range_m:.2f} m at {self.angle_deg:+.0f} deg"


NOTHING = Hit(math.inf, 0.0)


class _Geometry:
    """What every scan of one lidar shares: its beams' angles, their sines and cosines, and
    the beams in each sector asked about (worked out once per lidar, not per scan)."""

    def __init__(self, angles: FloatArray) -> None:
        self.angles = angles
        self.sin: FloatArray = np.sin(angles)
        self.cos: FloatArray = np.cos(angles)
        self._masks: dict[Sector, npt.NDArray[np.bool_]] = {}

    def mask(self, sector: Sector) -> npt.NDArray[np.bool_]:
        mask = self._masks.get(sector)
        if mask is None:
            low, high = sector
            centre, half = (low + high) / 2.0, (high - low) / 2.0
            delta = (self.angles - centre + math.pi) % (2.0 * math.pi) - math.pi  # wrapped
            mask = np.asarray(np.abs(delta) <= half + 1e-9)
            mask.flags.writeable = False
            if len(self._masks) < _MASKS_KEPT:
                self._masks[sector] = mask
        return mask


# Sectors kept per lidar: the shipped scenarios ask about a dozen; params that change every
# scan must not grow the cache without bound.
_MASKS_KEPT = 256


_geometries: dict[tuple[float, float, int], _Geometry] = {}
_GEOMETRIES_KEPT = 16  # lidars in one process: one per robot model, in practice


def _geometry(scan: LaserScan) -> _Geometry:
    key = (scan.angle_min, scan.angle_increment, len(scan.ranges))
    geometry = _geometries.get(key)
    if geometry is None:
        if len(_geometries) >= _GEOMETRIES_KEPT:
            _geometries.clear()
        geometry = _geometries[key] = _Geometry(scan.angles())
    return geometry


# The views of the last scans: every scenario of a robot decides on the same scan object
# (the store's), so the scan is prepared once for all of them. Keyed by the object's id, the
# scan held beside its view so that the id cannot be reused while the entry lives.
_VIEWS_KEPT = 64
_views: OrderedDict[int, tuple[LaserScan, ScanView]] = OrderedDict()


class ScanView:
    """One scan prepared once (angles, invalid beams) for any number of sector queries.

    :meth:`of` gives the view of a scan, made once however many scenarios ask; a view is
    read-only after it is made, so sharing it cannot change what any of them decides.
    """

    def __init__(self, scan: LaserScan) -> None:
        ranges = np.asarray(scan.ranges, dtype=np.float64)
        # Below range_min (or NaN) a beam carries no information: it counts as free space;
        # inf already means "nothing within range_max".
        valid = readings(ranges, scan.range_min)
        self.ranges: FloatArray = np.where(valid, ranges, np.inf)
        self._geometry = _geometry(scan)
        self.angles: FloatArray = self._geometry.angles
        self.range_max = float(scan.range_max)
        self._lateral: FloatArray | None = None
        self.memo: dict[object, object] = {}  # what callers worked out from this scan

    @classmethod
    def of(cls, scan: LaserScan) -> ScanView:
        """The view of ``scan``, shared by every caller that asks about the same object."""
        key = id(scan)
        held = _views.get(key)
        if held is not None and held[0] is scan:
            _views.move_to_end(key)
            return held[1]
        view = cls(scan)
        _views[key] = (scan, view)
        if len(_views) > _VIEWS_KEPT:
            _views.popitem(last=False)
        return view

    def _mask(self, sector: Sector) -> npt.NDArray[np.bool_]:
        return self._geometry.mask(sector)

    def _lateral_m(self) -> FloatArray:
        """Each beam's offset from the line of travel, range x |sin angle| (nan for an empty
        beam straight ahead or behind: never below a bound)."""
        if self._lateral is None:
            with np.errstate(invalid="ignore"):  # inf * sin(0) is nan: never a hit
                self._lateral = np.abs(self.ranges * self._geometry.sin)
        return self._lateral

    def _closest(self, mask: npt.NDArray[np.bool_]) -> Hit:
        if not mask.any():
            return NOTHING
        index = np.flatnonzero(mask)
        best = int(index[np.argmin(self.ranges[index])])
        value = float(self.ranges[best])
        return Hit(value, float(self.angles[best])) if math.isfinite(value) else NOTHING

    def closest(
        self, sector: Sector, within_m: float = math.inf, lateral_m: float = math.inf
    ) -> Hit:
        """The closest obstacle with its angle in ``sector``; with ``within_m``, only one
        closer than that, and with ``lateral_m``, only one whose offset from the line of
        travel (range x |sin angle|) is below that (NOTHING if there is none)."""
        mask = self._mask(sector)
        if math.isfinite(within_m) or math.isfinite(lateral_m):
            with np.errstate(invalid="ignore"):  # nan lateral offsets compare false
                mask = mask & (self.ranges < within_m) & (self._lateral_m() < lateral_m)
        return self._closest(np.asarray(mask))

    def sees(self, sector: Sector) -> bool:
        """Whether any beam of the scan points into ``sector`` (a partial field of view
        leaves some unseen)."""
        return bool(self._mask(sector).any())

    def openness(self, sector: Sector, horizon_m: float) -> float:
        """Mean range in ``sector``, each beam clipped at ``horizon_m``: higher is freer; 0
        for a sector with no beams (unseen is not free)."""
        mask = self._mask(sector)
        if not mask.any():
            return 0.0
        return float(np.minimum(self.ranges[mask], horizon_m).mean())

    def swept(self, direction: int, half_width_m: float, reach_m: float) -> Hit:
        """The closest obstacle the body (a disc of radius ``half_width_m``) would hit moving
        straight ahead (``direction`` +1) or back (-1) within ``reach_m`` of its centre."""
        with np.errstate(invalid="ignore"):  # inf * cos(pi/2) is nan: never a hit
            along = direction * self.ranges * self._geometry.cos
            lateral = self._lateral_m()
            mask = (self.ranges <= reach_m) & (along > 0.0) & (lateral <= half_width_m)
        return self._closest(np.asarray(mask))

    def boxed_in(self, reach_m: float) -> bool:
        """Obstacles within ``reach_m`` in each of the four quadrants (front, left, back, right)."""
        quadrants: tuple[Sector, ...] = (
            (-deg(45), deg(45)),
            (deg(45), deg(135)),
            (deg(135), deg(225)),
            (-deg(135), -deg(45)),
        )
        return all(self.closest(q).range_m <= reach_m for q in quadrants)

    def left_is_freer(self, left: Sector, right: Sector, horizon_m: float) -> bool:
        """Whether ``left`` is less obstructed than ``right``: the closer closest obstacle
        loses; on a tie, the less open sector loses; on a tie again, left wins. A side the
        lidar does not see at all loses to one it sees. Every scenario that must agree on a
        side (avoid_left and avoid_right) calls this one function, so they can never both
        claim the same obstacle."""
        seen_l, seen_r = self.sees(left), self.sees(right)
        if seen_l != seen_r:
            return seen_l
        near_l, near_r = self.closest(left).range_m, self.closest(right).range_m
        if min(near_l, near_r) < math.inf and not abs(near_l - near_r) <= TIE_M:
            return near_l > near_r
        open_l, open_r = self.openness(left, horizon_m), self.openness(right, horizon_m)
        if abs(open_l - open_r) > _OPENNESS_TIE_M:
            return open_l > open_r
        return True  # a symmetric obstacle: turn left (counter-clockwise), by convention


def describe_sector(sector: Sector) -> str:
    return f"[{math.degrees(sector[0]):+.0f}, {math.degrees(sector[1]):+.0f}] deg"

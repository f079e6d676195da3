"""Speed zones as the safety layer sees them: the zone table's speed_limit rows, and each
robot's newest pose, to cap the linear speed sent to a robot whose centre is in one.

Like Nav2's speed filter, a zone (CONTRACT.md, zone) is judged at the robot's centre, from
the newest odometry the bridge accepted (the bridge hands every valid one over: the pose
is never older than the robot's own report). Where zones overlap the lowest cap wins. A
keepout zone is the planner's: the bridge never moves a robot out of one (docs/BRIDGE.md).

The rows are read at the relay's start, again after every zone notification
(``pnav/db/zone/_``, the people's writers send it) and at least every ``refresh_s`` of
wall time in case one was lost or a writer did not notify; a failed read keeps the zones
last read (a speed cap stays rather than lapse while Postgres is away).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import asyncpg
import numpy as np
import numpy.typing as npt

from common.contract import zones as contract
from common.contract.zones import Zone

REFRESH_S = 0.5  # read the zones at least this often (wall s), as the planner does
FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class Cap:
    """The speed zone a robot is in: the cap on its linear speed, and the zone's name."""

    mps: float
    zone: str


class SpeedZones:
    """The speed_limit zones, as last read, and each robot's newest pose."""

    def __init__(
        self, refresh_s: float = REFRESH_S, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.zones: tuple[Zone, ...] = ()
        # the zones' boxes (x0, y0, x1, y1) and edges (x1, y1, y2, dx/dy, zone index), arrays
        self._boxes = np.zeros((0, 4))
        self._edges: tuple[FloatArray, FloatArray, FloatArray, FloatArray, IntArray] = (
            np.zeros(0),
            np.zeros(0),
            np.zeros(0),
            np.zeros(0),
            np.zeros(0, dtype=np.int64),
        )
        self.poses: dict[str, tuple[float, float, float]] = {}  # robot -> (stamp, x, y)
        self.refresh_s = refresh_s
        self._clock = clock
        self._read_at = -math.inf
        self._announced = True  # read at the start
        self.reads = 0

    # -- what the robot says -----------------------------------------------------------------
    def pose(self, robot: str, stamp: float, x: float, y: float) -> None:
        """A valid odometry came in: the newest (by stamp) is kept."""
        held = self.poses.get(robot)
        if held is None or stamp >= held[0]:
            self.poses[robot] = (stamp, x, y)

    def cap(self, robot: str) -> Cap | None:
        """The lowest cap of the speed zones the robot's centre is in (None: in none, or
        no pose yet). Every zone's bounding box first, then the even-odd test on the edges
        of those whose box holds the pose, all at once (numpy): a verdict stays well under a
        millisecond with the table's 256 zones of 100 vertices."""
        pose = self.poses.get(robot)
        if pose is None or not self.zones:
            return None
        _, x, y = pose
        boxes = self._boxes
        near = (boxes[:, 0] <= x) & (x <= boxes[:, 2]) & (boxes[:, 1] <= y) & (y <= boxes[:, 3])
        if not near.any():
            return None
        x1, y1, y2, slope, owner = self._edges
        if not near.all():  # only the edges of the zones whose box holds the pose
            edges = near[owner]
            x1, y1, y2, slope, owner = x1[edges], y1[edges], y2[edges], slope[edges], owner[edges]
        with np.errstate(invalid="ignore"):  # inf x 0 on a horizontal edge: spans nothing
            crossing = ((y1 > y) != (y2 > y)) & (x < slope * (y - y1) + x1)
        inside = np.bincount(owner[crossing], minlength=len(self.zones)) % 2 == 1
        best: Cap | None = None
        for i in np.flatnonzero(inside):
            zone = self.zones[int(i)]
            speed = zone.max_speed_mps
            if speed is not None and zone.applies_to(robot) and (best is None or speed < best.mps):
                best = Cap(speed, zone.name)
        return best

    # -- what people say ---------------------------------------------------------------------
    def set(self, zones: list[Zone]) -> None:
        self.zones = tuple(z for z in zones if z.kind == contract.SPEED_LIMIT)
        self._boxes = np.array([z.box for z in self.zones], dtype=np.float64).reshape(-1, 4)
        xs = [np.asarray(z.xs, dtype=np.float64) for z in self.zones]
        ys = [np.asarray(z.ys, dtype=np.float64) for z in self.zones]
        x1 = np.concatenate([np.roll(v, 1) for v in xs] or [np.zeros(0)])
        y1 = np.concatenate([np.roll(v, 1) for v in ys] or [np.zeros(0)])
        x2, y2 = np.concatenate(xs or [np.zeros(0)]), np.concatenate(ys or [np.zeros(0)])
        with np.errstate(divide="ignore", invalid="ignore"):
            slope = (x2 - x1) / (y2 - y1)  # inf on a horizontal edge, which spans no y
        owner = np.repeat(np.arange(len(self.zones)), [len(v) for v in xs]).astype(np.int64)
        self._edges = (x1, y1, y2, slope, owner)

    def changed(self) -> None:
        """A zone notification: read the table at the next chance."""
        self._announced = True

    def due(self) -> bool:
        return self._announced or self._clock() - self._read_at >= self.refresh_s

    async def read(self, conn: asyncpg.Connection) -> None:
        """Read the zone table (a failure leaves the zones as they were, and due)."""
        self._announced = False
        try:
            rows = await conn.fetch(contract.READ_SQL)
        except BaseException:
            self._announced = True
            raise
        self._read_at = self._clock()
        self.reads += 1
        self.set([Zone.of_row(r) for r in rows])

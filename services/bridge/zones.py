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

from common.contract import zones as contract
from common.contract.zones import Zone

REFRESH_S = 0.5  # read the zones at least this often (wall s), as the planner does


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
        no pose yet)."""
        pose = self.poses.get(robot)
        if pose is None or not self.zones:
            return None
        _, x, y = pose
        best: Cap | None = None
        for zone in self.zones:
            speed = zone.max_speed_mps
            if speed is None or not zone.applies_to(robot) or not zone.contains(x, y):
                continue
            if best is None or speed < best.mps:
                best = Cap(speed, zone.name)
        return best

    # -- what people say ---------------------------------------------------------------------
    def set(self, zones: list[Zone]) -> None:
        self.zones = tuple(z for z in zones if z.kind == contract.SPEED_LIMIT)

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

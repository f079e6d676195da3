"""The 2-D lidar: beam geometry for batch ray casting, and ranges with noise from the hits.

Beams are cast in batches (``rayTestBatch``, see physics.Scene.cast), never one at a time,
and never from inside the robot's own body, so they cannot hit it; ranges are still measured
from the centre, where an LDS-01 sits. Each beam is cast in two segments:

- the *far* segment, from ``far_offset`` (2 x footprint radius + 1 cm, clear of the robot's
  own bounding box at any heading) to ``range_max``, for every robot in one batch;
- the *near* segment, from just outside the footprint to ``far_offset``, only for robots
  that have something that close. A ray that starts inside its own robot's bounding box is
  tested against that robot's cylinder (pybullet's mask filter applies only after the test),
  which measured ten times the cost of a ray that starts outside it.

Ranges get Gaussian noise; a hit beyond ``range_max`` reads ``inf``, and a hit closer than
``range_min`` reads ``range_min`` (an obstacle there is real, and ``inf`` would tell a
controller the way is clear).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class LidarParams:
    beams: int = 360
    range_min: float = 0.12
    range_max: float = 3.5
    noise_sigma: float = 0.01
    # beam 0 points along the heading, as on the TurtleBot3's LDS-01 (0 to 2 pi, CCW)
    angle_min: float = 0.0

    @property
    def angle_increment(self) -> float:
        return 2.0 * math.pi / self.beams


class Lidar:
    """Ray geometry for a fixed mount (height, body radius) and the range computation."""

    def __init__(self, params: LidarParams, height_m: float, body_radius_m: float) -> None:
        self.params = params
        self.height = height_m
        # 1 mm outside the body: a ray never starts inside its own robot
        self.near_offset = body_radius_m + 0.001
        # beyond the bounding box of the body at any heading (its corner is at most 2 r away)
        self.far_offset = min(2.0 * body_radius_m + 0.01, params.range_max)
        if self.near_offset >= params.range_max:
            raise ValueError("the robot's body is larger than the lidar's range")
        angles = params.angle_min + params.angle_increment * np.arange(params.beams)
        self._cos = np.cos(angles)
        self._sin = np.sin(angles)

    def rays(self, poses: FloatArray, start: float, end: float) -> tuple[FloatArray, FloatArray]:
        """Ray starts and ends at distances ``start`` and ``end`` from each robot's centre,
        shape (len(poses) * beams, 3), for poses rows (x, y, yaw)."""
        n = self.params.beams
        x, y, yaw = poses[:, 0:1], poses[:, 1:2], poses[:, 2:3]
        # rotate the beam directions by each robot's yaw: cos(a + yaw), sin(a + yaw)
        cy, sy = np.cos(yaw), np.sin(yaw)
        dx = self._cos * cy - self._sin * sy
        dy = self._sin * cy + self._cos * sy
        starts = np.empty((len(poses), n, 3))
        ends = np.empty((len(poses), n, 3))
        starts[:, :, 0] = x + dx * start
        starts[:, :, 1] = y + dy * start
        starts[:, :, 2] = self.height
        ends[:, :, 0] = x + dx * end
        ends[:, :, 1] = y + dy * end
        ends[:, :, 2] = self.height
        return starts.reshape(-1, 3), ends.reshape(-1, 3)

    def far_rays(self, poses: FloatArray) -> tuple[FloatArray, FloatArray]:
        return self.rays(poses, self.far_offset, self.params.range_max)

    def near_rays(self, poses: FloatArray) -> tuple[FloatArray, FloatArray]:
        return self.rays(poses, self.near_offset, self.far_offset)

    def ranges(
        self,
        far: tuple[npt.NDArray[np.bool_], FloatArray],
        near: tuple[npt.NDArray[np.bool_], FloatArray] | None,
        rng: np.random.Generator,
    ) -> FloatArray:
        """Noisy ranges of one robot's beams from (hit, fraction) of the far segments and, if
        cast, of the near ones (a near hit hides whatever the far segment saw)."""
        p = self.params
        far_hit, far_fraction = far
        hit = far_hit.copy()
        true = self.far_offset + far_fraction * (p.range_max - self.far_offset)
        if near is not None:
            near_hit, near_fraction = near
            near_range = self.near_offset + near_fraction * (self.far_offset - self.near_offset)
            true = np.where(near_hit, near_range, true)
            hit |= near_hit
        # noise for every beam, hit or not, so the random stream does not depend on the scene
        noisy = true + rng.normal(0.0, p.noise_sigma, size=true.shape) if p.noise_sigma else true
        out = np.clip(noisy, p.range_min, p.range_max)
        out[~hit] = math.inf
        return out

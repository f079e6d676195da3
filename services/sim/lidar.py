"""The 2-D lidar: beam geometry for batch ray casting, and ranges with noise from the hits.

Beams start at the robot's centre, where an LDS-01 sits, at the lidar's height, and end at
``range_max``. The beams of every robot that scans in a physics step are cast together
(fleetcast.py), each robot's own body out of the way of its own beams only, so a beam never
hits its own robot and always sees the others.

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
    """Ray geometry for a fixed mount height, and the range computation."""

    def __init__(self, params: LidarParams, height_m: float) -> None:
        self.params = params
        self.height = height_m
        angles = params.angle_min + params.angle_increment * np.arange(params.beams)
        self._cos = np.cos(angles)
        self._sin = np.sin(angles)

    def rays(self, x: float, y: float, yaw: float) -> tuple[FloatArray, FloatArray]:
        """Ray starts and ends, shape (beams, 3), of a robot at (x, y, yaw)."""
        n = self.params.beams
        # the beam directions turned by the robot's yaw: cos(a + yaw), sin(a + yaw)
        cy, sy = math.cos(yaw), math.sin(yaw)
        dx = self._cos * cy - self._sin * sy
        dy = self._sin * cy + self._cos * sy
        starts = np.empty((n, 3))
        starts[:, 0] = x
        starts[:, 1] = y
        starts[:, 2] = self.height
        ends = np.empty((n, 3))
        ends[:, 0] = x + dx * self.params.range_max
        ends[:, 1] = y + dy * self.params.range_max
        ends[:, 2] = self.height
        return starts, ends

    def ranges(
        self, hit: npt.NDArray[np.bool_], fraction: FloatArray, rng: np.random.Generator
    ) -> FloatArray:
        """Noisy ranges of one robot's beams from the hit flags and fractions along the rays."""
        p = self.params
        true = fraction * p.range_max
        # noise for every beam, hit or not, so the random stream does not depend on the scene
        noisy = true + rng.normal(0.0, p.noise_sigma, size=true.shape) if p.noise_sigma else true
        out = np.clip(noisy, p.range_min, p.range_max)
        out[~hit] = math.inf
        return out

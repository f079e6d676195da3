"""The 2-D lidar: beam geometry, and ranges with noise from the hits.

The geometry is the robot model's lidar (common/robotmodel.py: beams, field of view, first
beam's angle, range, noise, mount height). Beams start at the robot's centre, at the lidar's
height, and end at ``range_max``. The beams of every robot that scans in a physics step are
cast together (fleetcast.py): a beam never meets its own robot and always the others.

Ranges get Gaussian noise; a hit beyond ``range_max`` reads ``inf``, and a hit closer than
``range_min`` reads ``range_min`` (an obstacle there is real, and ``inf`` would tell a
controller the way is clear).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from common.robotmodel import LidarModel

FloatArray = npt.NDArray[np.float64]


class Lidar:
    """Ray geometry for a fixed mount height, and the range computation."""

    def __init__(self, params: LidarModel) -> None:
        self.params = params
        self.height = params.height_m
        # beams outside a partial field of view do not exist: the ranges hold only the fov's
        angles = params.angle_min_rad + params.angle_increment * np.arange(params.beams)
        # each beam's direction from the heading
        self.cos = np.cos(angles)
        self.sin = np.sin(angles)

    def ranges(
        self, hit: npt.NDArray[np.bool_], fraction: FloatArray, rng: np.random.Generator
    ) -> FloatArray:
        """Noisy ranges of one robot's beams from the hit flags and fractions along the rays."""
        p = self.params
        true = fraction * p.range_max_m
        # noise for every beam, hit or not, so the random stream does not depend on the scene
        noisy = true + rng.normal(0.0, p.noise_m, size=true.shape) if p.noise_m else true
        out = np.clip(noisy, p.range_min_m, p.range_max_m)
        out[~hit] = math.inf
        return out

"""The fast dwa decides what a plain one does: on many seeded random scenes (clutter
ray-cast into a 720-beam lidar, paths that bend, speeds from a standstill to the top, and
a few params rows), pnav_local.dwa.choose picks the same command, reason and all, as the
slow reference in dwa_reference.py, with the disc and with a box footprint."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from common.contract.planned_path import PlannedPath
from common.contract.records import LaserScan, Odometry, Robot
from pnav_local.dwa import choose, command_for
from pnav_local.dwa_params import DwaParams
from tests.unit.local import dwa_reference

JACKAL = Robot("r1", 2.0, 4.0, 0.22, 270.0, max_linear_accel_mps2=10.0, max_angular_accel_rps2=20.0)
BOX = ((-0.254, -0.215), (0.254, -0.215), (0.254, 0.215), (-0.254, 0.215))  # the Jackal's
BEAMS, FOV = 720, math.radians(270.0)
ROWS: list[dict[str, Any]] = [
    {},
    {"dwa_steps": 20, "dwa_linear_samples": 12, "dwa_angular_samples": 25},
    {"dwa_clearance_cap_m": 1.5, "dwa_margin_m": 0.2, "dwa_min_travel_s": 1.0},
    {"dwa_clearance_weight": 3.0, "dwa_horizon_s": 2.0, "dwa_obstacle_range_m": 2.0},
]


def scene(rng: np.random.Generator, i: int) -> tuple[LaserScan, Odometry, PlannedPath]:
    """Posts and crates (discs) around the robot, as a 720-beam 270-degree lidar sees them."""
    k = int(rng.integers(0, 160))
    centres = rng.uniform(-4.0, 4.0, (k, 2))
    radii = rng.uniform(0.05, 0.3, k)
    keep = np.hypot(*centres.T) - radii > rng.uniform(0.2, 0.5)
    centres, radii = centres[keep], radii[keep]
    angles = -FOV / 2 + FOV / (BEAMS - 1) * np.arange(BEAMS)
    beams = np.column_stack([np.cos(angles), np.sin(angles)])
    along = beams @ centres.T
    disc = along**2 - ((centres**2).sum(axis=1) - radii**2)[None, :]
    t = np.where(disc >= 0.0, along - np.sqrt(np.maximum(disc, 0.0)), np.inf)
    ranges = np.where(t > 0.0, t, np.inf).min(axis=1, initial=np.inf)
    ranges = ranges + rng.normal(0.0, 0.005, BEAMS)
    ranges[ranges > 10.0] = np.inf
    scan = LaserScan(i, "r1", 0.1 * i, -FOV / 2, FOV / (BEAMS - 1), 0.1, 10.0, ranges.astype("f4"))
    v = float(rng.choice([0.0, 0.02, 0.1, 0.3, 1.0, 1.6, 2.0]))
    odom = Odometry(i, "r1", 0.1 * i, 0.0, 0.0, float(rng.uniform(-1.0, 1.0)), v,
                    float(rng.uniform(-2.0, 2.0)))  # fmt: skip
    length, bend = float(rng.uniform(0.3, 8.0)), float(rng.uniform(-4.0, 4.0))
    xs = np.arange(0.0, length + 0.05, 0.05)
    ys = bend * np.sin(xs / max(length, 1e-3) * math.pi / 2)
    path = PlannedPath(1, "r1", 0.0, 1, "goal", float(xs[-1]), float(ys[-1]),
                       tuple(xs.tolist()), tuple(ys.tolist()), length)  # fmt: skip
    return scan, odom, path


@pytest.mark.parametrize("polygon", [None, BOX], ids=["disc", "box"])
def test_the_fast_decision_is_the_plain_one(polygon: tuple[tuple[float, float], ...]) -> None:
    rng = np.random.default_rng(30)
    decided = refused_some = blocked = vetoed = 0
    for i in range(120 if polygon is None else 40):
        scan, odom, path = scene(rng, i + 1)
        p = DwaParams.read(ROWS[i % len(ROWS)])
        fast = choose(scan, odom, JACKAL, path, p, polygon)
        plain = dwa_reference.choose(scan, odom, JACKAL, path, p, polygon)
        assert (fast is None) == (plain is None), i
        if fast is None or plain is None:
            continue
        assert fast.ok.tolist() == plain.ok.tolist(), i
        assert fast.best == plain.best, i
        a, b = command_for(fast, path), command_for(plain, path)
        assert (a.linear, a.angular, a.reason) == (b.linear, b.angular, b.reason), i
        decided += 1
        refused_some += not fast.ok.all()
        blocked += fast.blocked
        vetoed += fast.vetoed > 0
    # the scenes reach the branches that matter: arcs refused for a hit, a blocked path
    assert decided > 0 and refused_some > decided // 4
    assert blocked > 0
    # and, for the box, winners the safety layer's test refused (veto.py)
    assert polygon is None or vetoed > 0

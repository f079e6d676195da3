"""dwa's work per decision is bounded whatever a strategy row, a scan or a path say: the
window's grid and steps fitted to the pose budget, the hits and path points capped, the
distance products computed a bounded slice at a time. Counted, never timed."""

from __future__ import annotations

import itertools
import logging
import math
import tracemalloc

import numpy as np
import pytest

import pnav_local.trajectories as tr
from common.contract.planned_path import PlannedPath
from common.contract.records import LaserScan, Odometry, Robot
from pnav_local.bounds import MAX_OBSTACLES, MAX_PATH_POINTS, PAIRS_PER_PRODUCT, nearest
from pnav_local.dwa import choose, command_for
from pnav_local.dwa_params import POSE_BUDGET, DwaParams, fit_budget, poses

JACKAL = Robot("r1", 2.0, 4.0, 0.22, 270.0, max_linear_accel_mps2=10.0, max_angular_accel_rps2=20.0)

# every size at the top of its documented range (docs/CONTROLLER.md, *dwa*)
WORST = {
    "dwa_horizon_s": 10.0,
    "dwa_steps": 50,
    "dwa_linear_samples": 50,
    "dwa_angular_samples": 100,
    "dwa_window_s": 5.0,
    "dwa_delay_s": 2.0,
    "dwa_lookahead_m": 20.0,
    "dwa_min_travel_s": 10.0,
    "dwa_obstacle_range_m": 100.0,
}


def cluttered(beams: int, seed: int = 3) -> LaserScan:
    """A full turn of ``beams`` beams, every one a hit 0.5 to 20 m away."""
    ranges = np.random.default_rng(seed).uniform(0.5, 20.0, beams).astype(np.float32)
    return LaserScan(1, "r1", 10.0, -math.pi, 2 * math.pi / beams, 0.1, 1000.0, ranges)


def dense_path(points: int, length: float = 30.0) -> PlannedPath:
    xs = tuple(np.linspace(0.0, length, points).tolist())
    return PlannedPath(1, "r1", 10.0, 1, "goal", length, 0.0, xs, (0.0,) * points, length)


def test_every_grid_in_the_documented_ranges_fits_the_budget() -> None:
    for grid in itertools.product((1, 2, 9, 25, 50), (1, 17, 21, 60, 100), (2, 10, 30, 50)):
        fitted = fit_budget(*grid)
        assert poses(*fitted) <= POSE_BUDGET, grid
        assert fitted[0] >= 1 and fitted[1] >= 1 and fitted[2] >= 2
        if poses(*grid) <= POSE_BUDGET:
            assert fitted == grid  # what fits is never touched
    # the row keeps its shape, each size about 1.5 x its default (9, 17, 10)
    assert fit_budget(50, 100, 50) == (14, 26, 15)
    assert DwaParams().asked is None and DwaParams.read({}).scaled == ""


def test_the_worst_documented_params_roll_out_within_the_budget() -> None:
    p = DwaParams.read(WORST)
    assert p.asked == (50, 100, 50)
    assert (p.linear_samples, p.angular_samples, p.steps) == (14, 26, 15)
    # a lidar of the contract's most beams, and a path of the contract's most points
    scan, path = cluttered(100_000), dense_path(100_000)
    for v in (0.0, 0.05, 1.0, 2.0):  # a standstill and a creep roll slow arcs out further
        tracemalloc.start()
        choice = choose(scan, Odometry(1, "r1", 10.0, 0.0, 0.0, 0.0, v, 0.0), JACKAL, path, p)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        assert choice is not None
        # rollouts x steps: the budget (clear_for rolls out at most as many again)
        assert len(choice.window.v) * p.steps <= POSE_BUDGET
        assert len(choice.local.points) <= MAX_PATH_POINTS
        # the scan alone holds 100,000 float64 ranges, angles and points: a few MB
        assert peak < 48 * 2**20, peak
    assert len(tr.merge_obstacles(np.column_stack([scan.ranges, scan.ranges]))) <= (MAX_OBSTACLES)


def test_the_reason_and_the_log_say_the_params_were_scaled(
    caplog: pytest.LogCaptureFixture,
) -> None:
    row = {"dwa_linear_samples": 40, "dwa_angular_samples": 90, "dwa_steps": 45}
    with caplog.at_level(logging.WARNING, logger="pnav.controller"):
        p = DwaParams.read(row)
        DwaParams.read(row)  # read on every scan: logged once
    warned = [r for r in caplog.records if "over the work budget" in r.getMessage()]
    assert len(warned) == 1
    assert warned[0].budget == POSE_BUDGET  # type: ignore[attr-defined]
    assert "dwa_steps=45" in warned[0].asked  # type: ignore[attr-defined]
    path = dense_path(2, 10.0)
    choice = choose(cluttered(360), Odometry(1, "r1", 10.0, 0, 0, 0, 1.0, 0), JACKAL, path, p)
    assert choice is not None
    reason = command_for(choice, path, p.scaled).reason
    used = f"{p.linear_samples} x {p.angular_samples} samples x {p.steps} steps"
    assert reason.endswith(
        f"; params scaled to {used} (asked 40 x 90 x 45: over the {POSE_BUDGET}-pose budget)"
    )


def test_distances_in_slices_are_the_distances_at_once() -> None:
    rng = np.random.default_rng(5)
    xs, ys = rng.uniform(-5, 5, (100, 40)), rng.uniform(-5, 5, (100, 40))
    obstacles = rng.uniform(-8, 8, (300, 2))
    assert xs.size * len(obstacles) > 8 * PAIRS_PER_PRODUCT  # many slices
    naive = np.hypot(
        xs.ravel()[:, None] - obstacles[None, :, 0], ys.ravel()[:, None] - obstacles[None, :, 1]
    ).min(axis=1)
    assert tr.distances(xs, ys, obstacles) == pytest.approx(naive.reshape(xs.shape), abs=1e-3)
    ends = rng.uniform(-5, 5, (2, 5000))
    line = np.column_stack([np.linspace(0, 10, 400), np.zeros(400)])
    assert tr.to_path(ends[0], ends[1], line) == pytest.approx(
        np.hypot(np.clip(ends[0], 0, 10) - ends[0], ends[1])
    )


def test_the_nearest_hits_are_kept_when_there_are_too_many() -> None:
    far = np.column_stack([np.linspace(5, 50, 3000), np.full(3000, 1.0)])
    near = np.array([[0.3, 0.0], [0.0, -0.4]])
    kept = nearest(np.vstack([far, near]), MAX_OBSTACLES)
    assert len(kept) == MAX_OBSTACLES
    assert {tuple(p) for p in near} <= {tuple(p) for p in kept}
    assert np.hypot(*kept.T).max() < np.hypot(*far[MAX_OBSTACLES].T)

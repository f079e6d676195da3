"""A Jackal's box fits a 0.45 m gap straight on but not at an angle: the sim's contact test
(pybullet, the body built from the model's polygon) and common.collision's grid check (the
planner's, and local planners') agree, pose by pose."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from common.collision import collides_on_grid, square_gaps
from common.footprint import Footprint
from common.robotmodel import load_model
from services.sim.mapserver import OCCUPIED
from services.sim.physics import CONTACT_TOLERANCE_M, Scene
from services.sim.world_spec import load_world
from tests.unit.sim.conftest import MakeWorld

pytestmark = pytest.mark.timeout(60)

JACKAL = load_model("jackal")
# a wall across the room at x 2.0 to 2.2, with a gap from y 1.30 to 1.75 (0.45 m: the box is
# 0.43 m wide, 0.626 m across at 30 degrees; the disc of the row, 0.44 m, fits too)
WALLS = [(2.0, 0.0, 2.2, 1.30), (2.0, 1.75, 2.2, 3.0)]
GAP_Y = (1.30 + 1.75) / 2


def jackal_scene(make_world: MakeWorld) -> Scene:
    robots = [{"id": "j1", "x": 1.0, "y": GAP_Y, "yaw": 0.0, "model": "jackal"}]
    return Scene(load_world(make_world(4.0, 3.0, WALLS, robots=robots)))


def grid_of(path: Path) -> tuple[np.ndarray, float, tuple[float, float]]:
    world = load_world(path)
    g = world.grid
    return g.cells == OCCUPIED, g.resolution, (g.origin[0], g.origin[1])


def test_straight_on_it_fits_at_an_angle_it_does_not(make_world: MakeWorld) -> None:
    scene = jackal_scene(make_world)
    occupied, res, origin = grid_of(make_world(4.0, 3.0, WALLS))
    fp = JACKAL.footprint
    try:
        for yaw, fits in ((0.0, True), (math.radians(30), False), (math.pi / 2, False)):
            scene.place(0, 2.1, GAP_Y, yaw)
            touching, _ = scene.probe(0, 2.1, GAP_Y)
            assert (touching == frozenset()) == fits, yaw
            on_grid = collides_on_grid(fp, (2.1, GAP_Y, yaw), occupied, res, origin)
            assert on_grid == (not fits), yaw
        # the disc of the same row fits at any heading: the reason for the polygon
        disc = Footprint.of(JACKAL.footprint_radius_m)
        assert not collides_on_grid(disc, (2.1, GAP_Y, 0.7), occupied, res, origin)
    finally:
        scene.close()


def test_the_sim_and_the_grid_check_agree_pose_by_pose(make_world: MakeWorld) -> None:
    scene = jackal_scene(make_world)
    occupied, res, origin = grid_of(make_world(4.0, 3.0, WALLS))
    fp = JACKAL.footprint
    rows, cols = np.nonzero(occupied)
    centres = np.stack([(cols + 0.5) * res + origin[0], (rows + 0.5) * res + origin[1]], axis=1)
    compared = touching_poses = 0
    try:
        for x in np.linspace(1.6, 2.6, 11):
            for dy in np.linspace(-0.06, 0.06, 7):
                for yaw in np.radians([0.0, 3.0, 8.0, 20.0, 45.0, 90.0, 170.0]):
                    pose = (float(x), GAP_Y + float(dy), float(yaw))
                    gap = float(np.min(square_gaps(fp, pose, centres, res / 2)))
                    if abs(gap - CONTACT_TOLERANCE_M) < 0.002:
                        continue  # on the boundary either may round its own way
                    scene.place(0, *pose)
                    touching, _ = scene.probe(0, pose[0], pose[1])
                    hit = collides_on_grid(fp, pose, occupied, res, origin, CONTACT_TOLERANCE_M)
                    assert bool(touching) == hit, (pose, gap, touching)
                    compared += 1
                    touching_poses += hit
    finally:
        scene.close()
    assert compared > 400 and 50 < touching_poses < compared - 50  # both kinds were seen


def test_turning_in_the_gap_is_blocked_and_driving_through_is_not(
    make_world: MakeWorld,
) -> None:
    scene = jackal_scene(make_world)
    try:
        scene.place(0, 2.1, GAP_Y, 0.0)
        # a turn that would put a corner into the wall keeps the old heading
        moved = scene.move(0, (2.1, GAP_Y, 0.0), (2.1, GAP_Y, 0.3))
        assert moved.yaw == 0.0 and moved.touching == frozenset({"wall"})
        # straight on, the whole way through is free
        x = 1.5
        while x < 2.7:
            moved = scene.move(0, (x, GAP_Y, 0.0), (x + 0.01, GAP_Y, 0.0))
            assert moved.fraction == 1.0 and not moved.touching, x
            x += 0.01
        # at 30 degrees the box stops at the wall
        scene.place(0, 1.5, GAP_Y, math.radians(30))
        x = 1.5
        while x < 2.7:
            moved = scene.move(0, (x, GAP_Y, math.radians(30)), (x + 0.01, GAP_Y, math.radians(30)))
            if moved.fraction < 1.0:
                break
            x += 0.01
        assert moved.fraction < 1.0 and "wall" in moved.touching and x < 2.0
    finally:
        scene.close()

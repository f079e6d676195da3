"""The contact test: what a robot touches and how much room it has, against robots moved
unchecked around it."""

from __future__ import annotations

import pytest

from services.sim.physics import Scene
from services.sim.world_spec import load_world
from tests.unit.sim.conftest import MakeWorld

pytestmark = pytest.mark.timeout(60)


def test_a_contact_test_sees_other_robots_where_they_were_last_placed(
    make_world: MakeWorld,
) -> None:
    robots = [{"id": "r1", "x": 1.0, "y": 1.0}, {"id": "r2", "x": 3.0, "y": 1.0}]
    scene = Scene(load_world(make_world(5.0, 3.0, robots=robots)))
    try:
        gap = 2 * 0.105  # between two Burgers' centres when they touch
        # r2 moved unchecked to 0.24 m from r1, within r1's clearance reach (0.3 m)
        scene.place(1, 1.0 + gap + 0.24, 1.0, 0.0)
        touching, clearance = scene.probe(0, 1.0, 1.0)
        assert not touching and abs(clearance - 0.24) < 1e-6
        # then far away: r1 meets nothing
        scene.place(1, 4.0, 1.0, 0.0)
        assert scene.probe(0, 1.0, 1.0) == (frozenset(), 0.3)
        # and touching it: r1 meets r2
        scene.place(1, 1.0 + gap, 1.0, 0.0)
        touching, clearance = scene.probe(0, 1.0, 1.0)
        assert touching == {"r2"} and clearance < 1e-6
    finally:
        scene.close()

"""common/footprint.py: the footprint's figures and tests, and models that give a polygon."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from common.collision import collides_with_points
from common.errors import ModelError
from common.footprint import Footprint, polygon_problem
from common.robotmodel import load_model

BOX = ((0.254, -0.215), (0.254, 0.215), (-0.254, 0.215), (-0.254, -0.215))


def test_the_jackal_model_gives_its_true_box() -> None:
    m = load_model("jackal")
    assert m.footprint_polygon == BOX
    fp = m.footprint
    assert fp.inscribed_m == pytest.approx(0.215)
    assert fp.circumscribed_m == pytest.approx(math.hypot(0.254, 0.215))
    assert m.footprint_radius_m == 0.22  # the disc, kept
    assert m.robot_row()["footprint_polygon"] == [list(v) for v in BOX]


def test_a_model_without_a_polygon_is_its_disc() -> None:
    m = load_model("turtlebot3_burger")
    assert m.footprint_polygon is None and m.robot_row()["footprint_polygon"] is None
    fp = m.footprint
    assert fp.is_disc and fp.inscribed_m == fp.circumscribed_m == 0.105


@pytest.mark.parametrize(
    ("polygon", "says"),
    [
        ([[0.2, 0.2], [-0.2, -0.2], [0.2, -0.2], [-0.2, 0.2]], "self-intersecting"),
        ([[1.0, -0.2], [1.5, -0.2], [1.5, 0.2], [1.0, 0.2]], "centre"),
        ([list(v) for v in BOX[::-1]], "counter-clockwise"),
        ([[0.2, -0.2], [".nan", 0.2], [-0.2, 0.0]], "two numbers"),
        ([[0.2, -0.2], [0.2, 0.2]], "3 to 64 vertices"),
        ("a box", "list of [x, y]"),
    ],
)
def test_a_model_file_with_a_bad_polygon_is_refused_naming_the_field(
    tmp_path: Path, polygon: object, says: str
) -> None:
    doc = yaml.safe_load(Path("models/jackal.yaml").read_text())
    doc["footprint_polygon"] = polygon
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ModelError) as caught:
        load_model(path)
    assert "footprint_polygon:" in str(caught.value) and says in str(caught.value)


def test_nan_is_refused() -> None:
    assert "finite" in str(polygon_problem([[0.2, -0.2], [math.nan, 0.2], [-0.2, 0.0]]))


def test_clearance_is_signed_distance_to_the_outline() -> None:
    fp = Footprint.of(0.22, BOX)
    pts = np.array([[0.0, 0.0], [1.254, 0.0], [0.0, 0.315], [0.354, 0.315]])
    got = fp.clearance(pts)
    assert got == pytest.approx([-0.215, 1.0, 0.1, math.hypot(0.1, 0.1)])
    disc = Footprint.of(0.2)
    assert disc.clearance(np.array([[0.5, 0.0]])) == pytest.approx([0.3])


def test_the_polygon_at_a_pose() -> None:
    fp = Footprint.of(0.22, BOX)
    at = fp.at(1.0, 2.0, math.pi / 2)
    assert at[0] == pytest.approx([1.215, 2.254])  # the front right corner, turned left


def test_travel_ahead_and_back_is_measured_from_the_edge() -> None:
    fp = Footprint.of(0.22, BOX)
    # a return 1 m ahead, 0.2 m left: the box's front edge is at x = 0.254
    assert fp.travel_m(np.array([[1.0, 0.2]])) == pytest.approx(0.746)
    # the disc of the same row would meet it sooner, and miss one beside the corner
    assert Footprint.of(0.22).travel_m(np.array([[1.0, 0.2]])) == pytest.approx(
        1.0 - math.sqrt(0.22**2 - 0.2**2)
    )
    assert Footprint.of(0.22).travel_m(np.array([[1.0, 0.221]])) == math.inf
    assert fp.travel_m(np.array([[1.0, 0.214]])) == pytest.approx(0.746)
    # behind: the back edge at x = -0.254
    assert fp.travel_m(np.array([[-0.5, 0.0], [2.0, 0.0]]), forward=False) == pytest.approx(0.246)
    assert fp.travel_m(np.array([[0.1, 0.1]])) == 0.0  # already inside


def test_collides_with_points_turns_with_the_pose() -> None:
    fp = Footprint.of(0.22, BOX)
    # a point 0.24 m to the left: clear of the box heading east, inside it heading north
    point = np.array([[0.0, 0.24]])
    assert not collides_with_points(fp, (0.0, 0.0, 0.0), point)
    assert collides_with_points(fp, (0.0, 0.0, math.pi / 2), point)
    assert collides_with_points(fp, (0.0, 0.0, 0.0), point, margin_m=0.03)


def test_first_contact_along_a_roll_out() -> None:
    from common.collision import first_contact

    fp = Footprint.of(0.22, BOX)
    # straight ahead at 0.1 m steps toward a return 1 m ahead: the front edge (0.254) meets
    # it once the centre is past 0.746 m
    poses = np.array([[0.1 * i, 0.0, 0.0] for i in range(12)])
    assert first_contact(fp, poses, np.array([[1.0, 0.1]])) == 8
    # a return beside the box's flank is never met driving straight; turning in place it is
    assert first_contact(fp, poses, np.array([[0.0, 0.24]])) is None
    turning = np.array([[0.0, 0.0, math.radians(10 * i)] for i in range(10)])
    assert first_contact(fp, turning, np.array([[0.0, 0.24]])) is not None
    assert first_contact(fp, poses, np.empty((0, 2))) is None
    # it agrees with the one-pose check at every pose
    points = np.array([[1.0, 0.1], [0.5, -0.3], [0.2, 0.25]])
    for i in range(len(turning)):
        one = collides_with_points(fp, tuple(turning[i]), points)
        assert one == (first_contact(fp, turning[i : i + 1], points) == 0)

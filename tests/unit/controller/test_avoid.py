"""avoid_left / avoid_right on synthetic scans: sectors, the head-on rule, params, limits."""

from __future__ import annotations

import dataclasses

import pytest

from common.contract.records import LaserScan
from common.controller_core.scenario import Command
from services.controller.avoid_left import AvoidLeft
from services.controller.avoid_right import AvoidRight
from tests.unit.controller.scans import BURGER, Obstacle, aisle, scan


def both(sweep: LaserScan, params: dict[str, object] | None = None) -> tuple[Command | None, ...]:
    return tuple(cls.decide(sweep, None, BURGER, params or {}) for cls in (AvoidLeft, AvoidRight))


def test_an_obstacle_front_right_makes_avoid_left_turn_left_slowly() -> None:
    left, right = both(scan((-40, -20, 0.30)))
    assert right is None
    assert left is not None
    assert left.angular > 0  # counter-clockwise
    assert 0 < left.linear <= 0.1
    assert "0.30 m" in left.reason and "front-right" in left.reason


def test_an_obstacle_front_left_makes_avoid_right_turn_right() -> None:
    left, right = both(scan((20, 40, 0.30)))
    assert left is None
    assert right is not None and right.angular < 0 and right.linear > 0
    assert "front-left" in right.reason


@pytest.mark.parametrize(
    "obstacles",
    [
        [(-3, 3, 0.30)],  # a pole dead ahead
        [(-60, 60, 0.30)],  # a wall across the whole front
        [(-50, -10, 0.30), (10, 50, 0.30)],  # a narrow passage: both sides at once
    ],
)
def test_a_symmetric_obstacle_gets_exactly_one_of_them(obstacles: list[Obstacle]) -> None:
    decisions = both(scan(*obstacles))
    assert sum(d is not None for d in decisions) == 1


def test_head_on_with_noise_never_gets_both_or_neither() -> None:
    for seed in range(40):
        decisions = both(scan((-30, 30, 0.30), noise=0.01, seed=seed))
        assert sum(d is not None for d in decisions) == 1, seed


def test_head_on_turns_away_from_the_more_obstructed_side() -> None:
    # Dead ahead, and the right also has something close: turn left, and vice versa.
    left, right = both(scan((-2, 2, 0.35), (-30, -25, 0.25)))
    assert left is not None and right is None
    left, right = both(scan((-2, 2, 0.35), (25, 30, 0.25)))
    assert left is None and right is not None
    # Same nearest range on both sides: the less open side loses.
    left, right = both(scan((-2, 2, 0.35), (-50, -10, 0.5)))
    assert left is not None and right is None


def test_a_clear_scan_or_far_obstacles_recommend_nothing() -> None:
    assert both(scan()) == (None, None)
    assert both(scan((-60, 60, 0.6))) == (None, None)  # beyond the 0.40 m default
    assert both(scan((90, 180, 0.2), (-180, -90, 0.2))) == (None, None)  # beside and behind
    assert both(scan((-80, -65, 0.2))) == (None, None)  # just outside the sector


def test_very_close_means_turning_in_place() -> None:
    left, _ = both(scan((-40, -30, 0.15)))
    assert left is not None and left.linear == 0.0 and left.angular > 0
    assert "in place" in left.reason


def test_params_come_from_the_strategy() -> None:
    sweep = scan((-40, -20, 0.30))
    assert both(sweep, {"avoid_distance_m": 0.25}) == (None, None)
    left, _ = both(sweep, {"avoid_distance_m": 0.5, "avoid_linear_mps": 0.08})
    assert left is not None and left.linear == pytest.approx(0.08)
    # a sector narrowed to 15 deg no longer sees the obstacle at -20..-40
    assert both(sweep, {"avoid_sector_deg": 15}) == (None, None)
    # an unusable value falls back to the default instead of disabling the scenario
    left, _ = both(sweep, {"avoid_distance_m": "far", "avoid_angular_rps": -3})
    assert left is not None and left.angular == pytest.approx(1.0)


def test_commands_are_clamped_to_the_robot_limits() -> None:
    slow = dataclasses.replace(BURGER, max_linear_mps=0.03, max_angular_rps=0.5)
    command = AvoidLeft.decide(scan((-40, -20, 0.30)), None, slow, {"avoid_angular_rps": 5})
    assert command is not None
    assert command.linear == pytest.approx(0.03) and command.angular == pytest.approx(0.5)


def test_invalid_beams_are_ignored_but_range_min_is_an_obstacle() -> None:
    sweep = scan((-40, -20, 0.05))  # below range_min: no information
    assert both(sweep) == (None, None)
    left, _ = both(scan((-40, -20, 0.12)))  # at range_min (stored as float32): an obstacle
    assert left is not None


@pytest.mark.parametrize("width", [0.9, 1.0, 1.2])
@pytest.mark.parametrize("offset", [0.0, 0.1])
@pytest.mark.parametrize("heading", [-15.0, 0.0, 15.0])
def test_walls_of_an_aisle_the_robot_drives_along_are_not_obstacles(
    width: float, offset: float, heading: float
) -> None:
    # In the middle of an aisle (or 10 cm off it), heading along it (or 15 deg off): the walls
    # are passed, not in the way. The racks of a warehouse must not push the robot about.
    sweep = aisle(width / 2 - offset, width / 2 + offset, heading, noise=0.01)
    assert both(sweep) == (None, None)


def test_in_an_aisle_an_obstacle_in_the_way_still_makes_the_robot_turn_away() -> None:
    # a pallet ahead and a little to the right, between the racks: turn left, away from it
    left, right = both(aisle(0.45, 0.45, 0.0, (-25, -5, 0.35)))
    assert right is None and left is not None and left.angular > 0
    assert "within 0.25 m of the way ahead" in left.reason
    # a wall the robot is heading into (30 deg off an aisle only 0.3 m to its side) counts
    left, right = both(aisle(0.3, 0.6, 40.0))
    assert left is None and right is not None and right.angular < 0


def test_the_lateral_band_is_a_strategy_param() -> None:
    sweep = scan((30, 40, 0.38))  # 0.19 to 0.24 m to the side
    assert both(sweep, {"avoid_lateral_m": 0.15}) == (None, None)
    _, right = both(sweep)
    assert right is not None
    # a band as wide as the aisle, and a longer reach: the walls count again (exactly one of
    # the pair turns, as for any obstacle on both sides)
    wide = {"avoid_lateral_m": 0.5, "avoid_distance_m": 0.6}
    assert sum(d is not None for d in both(aisle(0.45, 0.45), wide)) == 1

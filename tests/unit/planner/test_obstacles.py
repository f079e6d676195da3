"""The planner's obstacle layer: lidar hits the map does not explain, placed with the pose at
the scan's stamp, and the new plan they call for (no database, no engine)."""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable

import numpy as np
import pytest

from common.contract.records import LaserScan, Odometry
from common.planner_core.scenario import RobotInfo
from services.planner.routes import Router, Target
from services.planner.world_model import MapData, RobotState, World, see
from tests.unit.planner.test_closed_loop import RES, lidar


def room() -> np.ndarray:
    """6 x 3 m at 5 cm, walls all round."""
    occupied = np.zeros((60, 120), dtype=bool)
    occupied[0, :] = occupied[-1, :] = occupied[:, 0] = occupied[:, -1] = True
    return occupied


def planner(occupied: np.ndarray) -> tuple[Router, RobotState]:
    world = World()
    world.maps["room"] = MapData("room", "1", occupied, RES, (0.0, 0.0, 0.0))
    return Router(world, time.monotonic), RobotState(RobotInfo("r1", "room", 0.22, 2.84, 0.105))


def odom(stamp: float, x: float, y: float, yaw: float) -> Odometry:
    return Odometry(int(stamp * 100), "r1", stamp, x, y, yaw, 0.0, 0.0)


def test_the_pose_at_a_scan_is_interpolated_between_odometry_rows() -> None:
    _, robot = planner(room())
    robot.note_pose(odom(10.0, 1.0, 1.0, 3.0))
    robot.note_pose(odom(10.1, 1.1, 1.0, -3.0))  # across +-pi
    x, y, yaw = robot.pose_at(10.05) or (0.0, 0.0, 0.0)
    assert (x, y) == pytest.approx((1.05, 1.0))
    assert math.cos(yaw) == pytest.approx(math.cos(math.pi), abs=1e-3)
    assert robot.pose_at(10.12) == pytest.approx((1.1, 1.0, -3.0))  # the newest, 20 ms on
    assert robot.pose_at(10.3) is None  # nothing near it: the scan is not used
    assert robot.pose_at(9.0) is None


def test_only_hits_the_map_does_not_explain_are_obstacles() -> None:
    occupied = room()
    router, robot = planner(occupied)
    robot.note_pose(odom(5.0, 1.0, 1.5, 0.3))
    see(router.world, robot, lidar(occupied, 1.0, 1.5, 0.3, 5.0))
    assert robot.seen is not None and len(robot.seen.points) == 0  # the walls are on the map
    truth = occupied.copy()
    truth[26:34, 46:54] = True  # a 0.4 m crate at (2.5, 1.5)
    see(router.world, robot, lidar(truth, 1.0, 1.5, 0.3, 5.0))
    points = robot.seen.points
    assert len(points) > 5
    assert np.all(np.abs(points[:, 0] - 2.5) < 0.25) and np.all(np.abs(points[:, 1] - 1.5) < 0.25)


def test_a_new_obstacle_on_the_route_calls_for_one_new_plan() -> None:
    occupied = room()
    router, robot = planner(occupied)
    target = Target("goal", "1", 5.5, 1.5, 0.15, 0.0, 1)
    robot.note_pose(odom(1.0, 0.5, 1.5, 0.0))
    first = router.route_for(robot, 0.5, 1.5, target, 1.0)
    assert first.waypoints == 1  # straight across the empty room
    route = robot.route
    truth = occupied.copy()
    truth[26:34, 46:54] = True  # a crate at (2.5, 1.5), 1.8 m ahead
    for step in range(1, 6):  # the robot stands still; a scan every 0.2 s
        now = 1.0 + 0.2 * step
        robot.note_pose(odom(now, 0.5, 1.5, 0.0))
        see(router.world, robot, lidar(truth, 0.5, 1.5, 0.0, now))
        progress = router.route_for(robot, 0.5, 1.5, target, now)
        if step < 3:
            assert robot.route is route  # at most one such plan every 0.5 s of sim time
    assert robot.route is not route  # planned again, round the crate...
    assert progress.waypoints > 1 and progress.remaining_m > 5.0
    again = robot.route
    robot.note_pose(odom(3.0, 0.5, 1.5, 0.0))
    see(router.world, robot, lidar(truth, 0.5, 1.5, 0.0, 3.0))
    router.route_for(robot, 0.5, 1.5, target, 3.0)
    assert robot.route is again  # ...once: the same crate is not new any more


def front_lidar(truth: np.ndarray, x: float, y: float, yaw: float, stamp: float) -> LaserScan:
    """A 270-degree lidar (the Jackal's): the 360-beam sweep's beams from -135 to +134 deg."""
    full = lidar(truth, x, y, yaw, stamp)
    ranges = np.concatenate((full.ranges[225:], full.ranges[:135]))
    return dataclasses.replace(full, angle_min=-math.radians(135), ranges=ranges)


def near_crate(robot: RobotState) -> int:
    """How many known obstacles are at the crate at (2.5, 1.5)."""
    assert robot.seen is not None
    points = robot.seen.points
    return int(np.sum((np.abs(points[:, 0] - 2.5) < 0.25) & (np.abs(points[:, 1] - 1.5) < 0.25)))


def test_an_obstacle_out_of_the_lidars_view_is_remembered_until_a_beam_passes_or_it_is_old() -> (
    None
):
    occupied = room()
    router, robot = planner(occupied)
    truth = occupied.copy()
    truth[26:34, 46:54] = True  # a crate at (2.5, 1.5), 1 m ahead of the robot at first

    def at(stamp: float, yaw: float, scan: Callable[..., LaserScan], world: np.ndarray) -> int:
        robot.note_pose(odom(stamp, 1.5, 1.5, yaw))
        see(router.world, robot, scan(world, 1.5, 1.5, yaw, stamp))
        return near_crate(robot)

    assert at(5.0, 0.0, front_lidar, truth) > 5  # seen ahead
    seen = near_crate(robot)
    assert at(5.2, math.pi, front_lidar, truth) == seen  # turned round: behind, out of view, kept
    assert at(124.9, math.pi, front_lidar, truth) == seen  # 119.9 s unseen: still kept
    assert at(125.1, math.pi, front_lidar, truth) == 0  # 120.1 s unseen: forgotten

    assert at(126.0, 0.0, front_lidar, truth) > 5  # seen again
    assert at(126.2, math.pi, lidar, occupied) == 0  # the crate went: a 360-degree beam passes


def test_a_hit_is_placed_in_the_cell_behind_the_surface_it_measured() -> None:
    occupied = room()
    router, robot = planner(occupied)
    truth = occupied.copy()
    truth[20:40, 50:60] = True  # a crate whose west face is the cell boundary x = 2.5
    robot.note_pose(odom(5.0, 1.5, 1.5, 0.0))
    # 41 beams at the face 1 m ahead, each reading 1 mm short (the lidar's noise)
    angles = np.linspace(-0.2, 0.2, 41)
    ranges = ((1.0 - 0.001) / np.cos(angles)).astype(np.float32)
    scan = LaserScan(50, "r1", 5.0, -0.2, 0.01, 0.12, 3.5, ranges)
    see(router.world, robot, scan)
    assert robot.seen is not None
    points = robot.seen.points
    assert len(points) > 5
    # in the crate's cells (x >= 2.5), not the free ones in front: the inflation grows from
    # the crate's own cells; one point per 5 cm cell
    assert np.all(points[:, 0] >= 2.5) and np.all(points[:, 0] < 2.55)
    cells = {(math.floor(x / RES), math.floor(y / RES)) for x, y in points}
    assert len(cells) == len(points) < 41


def test_an_obstacle_seen_again_is_not_remembered_twice() -> None:
    occupied = room()
    router, robot = planner(occupied)
    truth = occupied.copy()
    truth[26:34, 46:54] = True
    counts = []
    for step in range(5):  # standing still, the same crate every 0.2 s
        stamp = 5.0 + 0.2 * step
        robot.note_pose(odom(stamp, 1.5, 1.5, 0.0))
        see(router.world, robot, lidar(truth, 1.5, 1.5, 0.0, stamp))
        counts.append(near_crate(robot))
    assert counts == [counts[0]] * 5  # the newest scan's hits replace the remembered ones

"""The map from a ROS 2 map server (robot-link file ``map: /map``): its OccupancyGrid,
published TRANSIENT_LOCAL before the bridge starts, replaces the world map's grid."""

from __future__ import annotations

import math
from typing import Any

import asyncpg
import numpy as np
import pytest
import zenoh

from common import ros2types
from common.config import ZenohSettings
from common.contract import rmw_zenoh as rz
from common.robotlink import RobotLinkSettings
from common.ros2node import Ros2Node
from pnav._testing import eventually
from tests.contract.bridge.conftest import FakeSim
from tests.contract.ros2.conftest import start_ros2_bridge

pytestmark = pytest.mark.slow

MAP_ROW = (
    "SELECT resolution_m, origin_x, origin_y, origin_yaw, width, height, grid, source FROM map"
)


def grid_msg(cells: list[int], width: int, height: int, frame: str = "map") -> Any:
    origin = ros2types.message(
        "geometry_msgs/msg/Pose",
        position=ros2types.message("geometry_msgs/msg/Point", x=-2.0, y=-1.0, z=0.0),
        orientation=ros2types.quaternion(0.0),
    )
    info = ros2types.message(
        "nav_msgs/msg/MapMetaData",
        map_load_time=ros2types.time_msg(0.0),
        resolution=0.05,
        width=width,
        height=height,
        origin=origin,
    )
    return ros2types.message(
        ros2types.OCCUPANCY_GRID,
        header=ros2types.header(0.0, frame),
        info=info,
        data=np.asarray(cells, dtype=np.int8),
    )


async def _map_row(db_url: str) -> asyncpg.Record:
    conn = await asyncpg.connect(db_url)
    try:
        return await conn.fetchrow(MAP_ROW)
    finally:
        await conn.close()


async def test_a_map_servers_grid_becomes_the_worlds_map(
    db_url: str, zenoh_settings: ZenohSettings, sim: FakeSim, ros_session: zenoh.Session
) -> None:
    map_server = Ros2Node(ros_session, 0, "map_server")
    publisher = map_server.publisher("/map", ros2types.OCCUPANCY_GRID, rz.LATCHED)
    # published once, before the bridge is there: a late subscription still gets it
    publisher.put(grid_msg([0, 100, -1, 0, 0, 100], 3, 2), reliable=True)
    link = RobotLinkSettings(link="ros2", map_topic="/map")
    bridge, runtime = await start_ros2_bridge(db_url, zenoh_settings, sim, link)
    try:
        ros_map = bridge.ros2_map
        assert ros_map is not None
        await eventually(lambda: ros_map.maps_written >= 1, within=30, what="the ROS map")
        row = await _map_row(db_url)
        assert (row["width"], row["height"], row["resolution_m"]) == (3, 2, 0.05)
        assert (row["origin_x"], row["origin_y"], row["origin_yaw"]) == (-2.0, -1.0, 0.0)
        assert bytes(row["grid"]) == bytes([0, 100, 255, 0, 0, 100])  # -1: unknown, 255
        assert row["source"] == "ros2:/map"

        # a bad grid is counted and leaves the map alone; a new good one replaces it
        publisher.put(grid_msg([0, 101, 0, 0], 2, 2), reliable=True)
        publisher.put(grid_msg([0, 0, 0, 0], 2, 2, frame="odom"), reliable=True)
        publisher.put(grid_msg([0, 0, 0], 2, 2), reliable=True)  # 3 cells for 2 x 2
        malformed = bridge.counters.malformed
        await eventually(
            lambda: (
                malformed[("ros2/map", "out_of_range")] == 2
                and malformed[("ros2/map", "wrong_frame")] == 1
            ),
            what="three bad maps counted",
        )
        assert ros_map.maps_written == 1
        publisher.put(grid_msg([100] * 4, 2, 2), reliable=True)
        await eventually(lambda: ros_map.maps_written == 2, what="the new map")
        row = await _map_row(db_url)
        assert (row["width"], row["height"], bytes(row["grid"])) == (2, 2, bytes([100] * 4))
        # the world's stations still stand on it
        conn = await asyncpg.connect(db_url)
        try:
            assert await conn.fetchval("SELECT count(*) FROM charging_station") == 1
        finally:
            await conn.close()
        assert math.isfinite(row["resolution_m"])
    finally:
        map_server.close()
        await bridge.stop()
        await runtime.close()

"""The bridge on the ROS 2 link: a ROS 2 robot's scan, odom and battery_state become rows,
validated as the sim's are; decisions go out as Twist or TwistStamped; hostile input is
counted and dropped."""

from __future__ import annotations

import asyncio
import math
import time

import asyncpg
import pytest

from common import ros2types
from common.contract import rmw_zenoh as rz
from pnav._testing import eventually
from services.bridge import Bridge
from services.bridge.ros2link import MAX_RATE_HZ
from tests.contract.bridge.conftest import SETTLE_S, FakeSim, command
from tests.contract.ros2.conftest import Robot, battery_msg, odom_msg, scan_msg

pytestmark = pytest.mark.slow


async def _rows(db_url: str, table: str) -> list[asyncpg.Record]:
    conn = await asyncpg.connect(db_url)
    try:
        return list(await conn.fetch(f"SELECT * FROM {table} ORDER BY id"))
    finally:
        await conn.close()


async def test_a_ros2_robots_sensors_become_rows(
    ros2_bridge: Bridge, ros_session, db_url: str
) -> None:
    robot = Robot(ros_session)
    await asyncio.sleep(SETTLE_S)
    robot.put(robot.odom, odom_msg(stamp=2.5, x=1.25, y=-0.5, yaw=0.75, linear=0.1, angular=-0.2))
    robot.put(robot.scan, scan_msg(stamp=2.5))
    robot.put(robot.battery, battery_msg(stamp=2.5))
    await eventually(
        lambda: sum(ros2_bridge.counters.rows_written.values()) >= 3, what="three rows"
    )
    (odom,) = await _rows(db_url, "odometry")
    assert (odom["robot_id"], odom["stamp"], odom["x"], odom["y"]) == ("r1", 2.5, 1.25, -0.5)
    assert odom["yaw"] == pytest.approx(0.75)
    assert (odom["linear_mps"], odom["angular_rps"]) == (0.1, -0.2)
    (scan,) = await _rows(db_url, "laser_scan")
    assert len(scan["ranges"]) == 360 and scan["seq"] == 1  # the attachment's sequence number
    (battery,) = await _rows(db_url, "battery")
    assert battery["energy_wh"] == pytest.approx(15.0, rel=1e-6)
    assert battery["capacity_wh"] == pytest.approx(19.98, rel=1e-6)
    assert battery["power_w"] == pytest.approx(3.0, rel=1e-6)
    robot.node.close()


async def test_map_to_odom_from_tf_moves_the_pose_into_the_map(
    ros2_bridge: Bridge, ros_session, db_url: str
) -> None:
    robot = Robot(ros_session)
    await asyncio.sleep(SETTLE_S)
    tf = ros2types.message(
        ros2types.TF_MESSAGE,
        transforms=[
            ros2types.message(
                "geometry_msgs/msg/TransformStamped",
                header=ros2types.header(1.0, "map"),
                child_frame_id="r1/odom",
                transform=ros2types.message(
                    "geometry_msgs/msg/Transform",
                    translation=ros2types.message("geometry_msgs/msg/Vector3", x=1.0, y=2.0, z=0.0),
                    rotation=ros2types.quaternion(math.pi / 2),
                ),
            )
        ],
    )
    robot.put(robot.tf, tf)
    await eventually(lambda: "r1" in ros2_bridge.ros2.map_odom, what="map -> odom")  # type: ignore[union-attr]
    robot.put(robot.odom, odom_msg(x=1.0, y=0.0, yaw=0.0))
    await eventually(lambda: ros2_bridge.counters.rows_written["odometry"] >= 1, what="a row")
    (odom,) = await _rows(db_url, "odometry")
    assert (odom["x"], odom["y"], odom["yaw"]) == pytest.approx((1.0, 3.0, math.pi / 2))
    robot.node.close()


async def test_decisions_go_out_as_twist_stamped_or_twist_per_robot(
    ros2_bridge: Bridge, ros_session, sim: FakeSim, db_url: str
) -> None:
    r1 = Robot(ros_session, "/r1", stamped=True)
    r2 = Robot(ros_session, "/r2", stamped=False)
    await asyncio.sleep(SETTLE_S)
    conn = await asyncpg.connect(db_url)
    try:
        await command(conn, sim, 0.1, 0.5, robot="r1")
        await command(conn, sim, 0.05, -0.5, robot="r2")
    finally:
        await conn.close()
    await eventually(lambda: r1.cmd and r2.cmd, what="both cmd_vel")
    assert r1.cmd[0] == (0.1, 0.5) and r2.cmd[0] == (0.05, -0.5)
    r1.node.close()
    r2.node.close()


async def test_hostile_ros2_input_is_counted_and_dropped(
    ros2_bridge: Bridge, ros_session, db_url: str
) -> None:
    robot = Robot(ros_session)
    await asyncio.sleep(SETTLE_S)
    good = ros2types.encode(ros2types.ODOMETRY, odom_msg())
    scan_key = robot.scan.key
    odom_key = robot.odom.key
    robot.put_raw(odom_key, good[: len(good) // 2])  # truncated
    robot.put_raw(scan_key, good)  # an Odometry on the scan's key
    wrong_hash = odom_key.rsplit("/", 1)[0] + "/RIHS01_" + "0" * 64
    robot.put_raw(wrong_hash, good)
    wrong_type = rz.topic_key(
        0, "/r1/odom", ros2types.TWIST, ros2types.ros_type(ros2types.TWIST).hash
    )
    robot.put_raw(
        wrong_type,
        ros2types.encode(
            ros2types.TWIST,
            ros2types.message(
                ros2types.TWIST,
                linear=ros2types.message("geometry_msgs/msg/Vector3", x=0.0, y=0.0, z=0.0),
                angular=ros2types.message("geometry_msgs/msg/Vector3", x=0.0, y=0.0, z=0.0),
            ),
        ),
    )
    robot.put(robot.scan, scan_msg(beams=359))  # the robot's lidar has 360
    robot.put(robot.odom, odom_msg(x=math.nan))
    flood = ros2types.encode(ros2types.ODOMETRY, odom_msg(x=9.0))
    started = time.monotonic()
    for _ in range(10_000):
        robot.put_raw(odom_key, flood)
    malformed = ros2_bridge.counters.malformed
    await eventually(
        lambda: (
            malformed[("ros2/odom", "too_fast")] > 0
            and malformed[("ros2/odom", "bad_cdr")] == 1
            and malformed[("ros2/scan", "bad_cdr")] == 1
            and malformed[("ros2/odom", "wrong_type_hash")] == 1
            and malformed[("ros2/odom", "wrong_type")] == 1
            and malformed[("ros2/scan", "beam_count")] == 1
            and malformed[("ros2/odom", "not_finite")] == 1
        ),
        within=30,
        what="every kind counted",
    )
    await eventually(
        lambda: ros2_bridge.counters.messages_in["ros2/odom"] >= 10_000, what="the flood read"
    )
    # the bridge reads the flood after the puts, over as many seconds as it takes
    seconds = time.monotonic() - started
    rows = await _rows(db_url, "odometry")
    assert all(math.isfinite(r["x"]) for r in rows)
    # beyond MAX_RATE_HZ in any one second the flood never became rows
    assert len(rows) <= MAX_RATE_HZ * (math.ceil(seconds) + 2)
    assert len(rows) < 10_000
    assert not await _rows(db_url, "laser_scan")
    # still working
    await asyncio.sleep(1.1)
    robot.put(robot.scan, scan_msg(stamp=3.0))
    await eventually(lambda: ros2_bridge.counters.rows_written["laser_scan"] >= 1, what="a scan")
    robot.node.close()


async def test_a_mostly_nan_ros2_scan_is_stored_as_the_contract_means_it(
    ros2_bridge: Bridge, ros_session, db_url: str
) -> None:
    robot = Robot(ros_session)
    await asyncio.sleep(SETTLE_S)
    ranges = [math.nan] * 300 + [1.0] * 58 + [-math.inf, math.inf]  # REP 117
    robot.put(robot.scan, scan_msg(stamp=4.0, ranges=ranges))
    await eventually(lambda: ros2_bridge.counters.rows_written["laser_scan"] >= 1, what="a scan")
    (scan,) = await _rows(db_url, "laser_scan")
    stored = list(scan["ranges"])
    assert stored[:300] == [math.inf] * 300  # no return, not an obstacle
    assert stored[300:358] == [1.0] * 58
    assert stored[358] == pytest.approx(0.12)  # too close: range_min, an obstacle
    assert stored[359] == math.inf
    assert ros2_bridge.counters.ros2_beams == {"nan": 300, "too_close": 1}
    assert ros2_bridge.counters.malformed_total() == 0
    robot.node.close()

"""A ROS 2 robot with no pybullet sim (``clock: ros``): the bridge's ROS 2 link publishes the
stack's clock, ``pnav/sim/clock``, in ROS time: the system clock, or ROS ``/clock`` with
``use_sim_time``. Rows keep the robot's stamps, and the services' clock follows ROS time."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator

import asyncpg
import pytest
import zenoh

from common import bus, ros2types
from common.clock import SimClock
from common.config import ZenohSettings
from common.robotlink import RobotLinkSettings
from pnav._testing import eventually
from services.bridge import Bridge
from tests.contract.bridge.conftest import SETTLE_S, FakeSim, command
from tests.contract.ros2.conftest import Robot, odom_msg, scan_msg, start_ros2_bridge

pytestmark = pytest.mark.slow


@pytest.fixture
async def services_clock(zenoh_settings: ZenohSettings) -> AsyncIterator[SimClock]:
    """The clock a service runs on, in a session of its own."""
    session = await asyncio.to_thread(bus.open_session, zenoh_settings)
    clock = SimClock()
    clock.attach(session)
    try:
        yield clock
    finally:
        clock.close()
        session.close()


async def _bridge(
    db_url: str, zenoh_settings: ZenohSettings, sim: FakeSim, use_sim_time: bool
) -> Bridge:
    link = RobotLinkSettings(link="ros2", clock="ros", use_sim_time=use_sim_time)
    bridge, _ = await start_ros2_bridge(db_url, zenoh_settings, sim, link)
    return bridge


async def _stop(bridge: Bridge) -> None:
    await bridge.stop()
    await bridge.runtime.close()


async def test_with_no_sim_the_stack_runs_on_the_robots_system_clock(
    db_url: str,
    zenoh_settings: ZenohSettings,
    sim: FakeSim,
    ros_session: zenoh.Session,
    services_clock: SimClock,
) -> None:
    # the fake sim serves the world only: no pnav/sim/clock from it
    bridge = await _bridge(db_url, zenoh_settings, sim, use_sim_time=False)
    robot = Robot(ros_session, "/r1")
    try:
        await eventually(lambda: services_clock.started, what="the services' clock")
        first = services_clock.now()
        assert abs(first - time.time()) < 5.0  # ROS time: the system clock
        await asyncio.sleep(0.5)
        assert services_clock.now() > first  # it advances
        await asyncio.sleep(SETTLE_S)
        stamp = time.time()
        robot.put(robot.odom, odom_msg(stamp=stamp))
        robot.put(robot.scan, scan_msg(stamp=stamp))
        await eventually(
            lambda: (
                bridge.counters.rows_written["odometry"] >= 1
                and bridge.counters.rows_written["laser_scan"] >= 1
            ),
            what="rows",
        )
        conn = await asyncpg.connect(db_url)
        try:
            odom = await conn.fetchval("SELECT stamp FROM odometry")
            scan = await conn.fetchval("SELECT stamp FROM laser_scan")
            assert odom == pytest.approx(stamp, abs=1e-6) and scan == odom
            # a decision stamped in ROS time is fresh on the bridge's clock: it goes out
            await command(conn, sim, 0.1, 0.0, robot="r1", stamp=bridge.runtime.clock.now())
        finally:
            await conn.close()
        await eventually(lambda: robot.cmd, what="cmd_vel")
        assert robot.cmd[0] == (0.1, 0.0)
    finally:
        robot.node.close()
        await _stop(bridge)


async def test_with_use_sim_time_the_stack_runs_on_ros_clock(
    db_url: str,
    zenoh_settings: ZenohSettings,
    sim: FakeSim,
    ros_session: zenoh.Session,
    services_clock: SimClock,
) -> None:
    bridge = await _bridge(db_url, zenoh_settings, sim, use_sim_time=True)
    gazebo = Robot(ros_session, "/r1")
    clock = gazebo.node.publisher("/clock", ros2types.CLOCK)
    try:
        await asyncio.sleep(SETTLE_S)
        assert not services_clock.started  # nothing before the first /clock
        clock.put(
            ros2types.message(ros2types.CLOCK, clock=ros2types.time_msg(100.25)), reliable=True
        )
        await eventually(lambda: services_clock.now() == 100.25, what="ROS time 100.25")
        clock.put(
            ros2types.message(ros2types.CLOCK, clock=ros2types.time_msg(101.5)), reliable=True
        )
        await eventually(lambda: services_clock.now() == 101.5, what="ROS time 101.5")
        # garbage on /clock is counted, and time stays where it was
        gazebo.put_raw(clock.key, b"\x00\x01\x00\x00\x01")
        await eventually(
            lambda: bridge.counters.malformed[("ros2/clock", "bad_cdr")] == 1, what="counted"
        )
        gazebo.put(gazebo.odom, odom_msg(stamp=101.5))
        await eventually(lambda: bridge.counters.rows_written["odometry"] >= 1, what="a row")
        assert services_clock.now() == 101.5 and bridge.runtime.clock.now() == 101.5
        conn = await asyncpg.connect(db_url)
        try:
            assert await conn.fetchval("SELECT stamp FROM odometry") == 101.5
        finally:
            await conn.close()
    finally:
        gazebo.node.close()
        await _stop(bridge)

"""Fixtures for the ROS 2 link: the bridge in-process on the ROS 2 link, and a ROS 2 robot
played by a plain Zenoh session speaking rmw_zenoh (common.ros2node), on a real router."""

from __future__ import annotations

import asyncio
import math
from collections.abc import AsyncIterator
from typing import Any

import numpy as np
import pytest
import zenoh

from common import bus, ros2types
from common.config import ServiceConfig, ZenohSettings
from common.robotlink import RobotLinkSettings, RobotTopics
from common.ros2node import Publisher, Ros2Node
from common.runtime import Runtime
from pnav._testing import as_service_role, eventually
from services.bridge import Bridge
from services.sim import ros2wire
from tests.contract.bridge.conftest import FAST, SETTLE_S, FakeSim
from tests.unit.bridge import payloads


class Robot:
    """A ROS 2 robot under ``/r1``: publishes its sensors, hears cmd_vel."""

    def __init__(self, session: zenoh.Session, namespace: str = "/r1", stamped: bool = False):
        self.node = Ros2Node(session, 0, "turtlebot", namespace)
        self.scan = self.node.publisher("scan", ros2types.LASER_SCAN)
        self.odom = self.node.publisher("odom", ros2types.ODOMETRY)
        self.battery = self.node.publisher("battery_state", ros2types.BATTERY_STATE)
        self.tf = self.node.publisher("/tf", ros2types.TF_MESSAGE)
        self.cmd: list[tuple[float, float]] = []
        kind = ros2types.TWIST_STAMPED if stamped else ros2types.TWIST
        self.cmd_type = kind
        self.node.subscription("cmd_vel", kind, self._on_cmd)

    def _on_cmd(self, key: str, payload: bytes, att: bytes | None) -> None:
        msg = ros2types.decode(self.cmd_type, payload)
        twist = msg.twist if self.cmd_type == ros2types.TWIST_STAMPED else msg
        self.cmd.append((twist.linear.x, twist.angular.z))

    def put(self, publisher: Publisher, msg: Any) -> None:
        publisher.put(msg, reliable=True)

    def put_raw(self, key: str, payload: bytes) -> None:
        self.node.session.put(key, payload, congestion_control=zenoh.CongestionControl.BLOCK)


def scan_msg(stamp: float = 1.0, beams: int = 360, **body: Any) -> Any:
    return ros2wire.scan_msg(
        {**payloads.scan(stamp=stamp, ranges=[1.0] * beams), **body}, "r1/base_scan"
    )


def odom_msg(stamp: float = 1.0, **body: Any) -> Any:
    return ros2wire.odom_msg({**payloads.odom(stamp=stamp), **body}, "r1/odom", "r1/base_footprint")


def battery_msg(stamp: float = 1.0, **body: Any) -> Any:
    return ros2wire.battery_msg({**payloads.battery(stamp=stamp), "power_w": 3.0, **body}, "r1")


@pytest.fixture
async def ros_session(zenoh_settings: ZenohSettings) -> AsyncIterator[zenoh.Session]:
    session = await asyncio.to_thread(bus.open_session, zenoh_settings)
    try:
        yield session
    finally:
        session.close()


@pytest.fixture
async def sim(zenoh_settings: ZenohSettings) -> AsyncIterator[FakeSim]:
    session = await asyncio.to_thread(bus.open_session, zenoh_settings)
    fake = FakeSim(session)
    try:
        yield fake
    finally:
        fake.close()


async def start_ros2_bridge(
    db_url: str, zenoh_settings: ZenohSettings, sim: FakeSim, link: RobotLinkSettings
) -> tuple[Bridge, Runtime]:
    """A started bridge on the ROS 2 link ``link``, its world (r1, r2) served by ``sim``."""
    role_url = await as_service_role(db_url, "bridge")
    config = ServiceConfig(
        service="bridge", database_url=role_url, zenoh=zenoh_settings, instance="test-bridge"
    )
    sim.serve_world(payloads.world(robots=("r1", "r2")))
    await asyncio.sleep(SETTLE_S)
    runtime = await Runtime.open(config)
    bridge = Bridge(runtime, FAST, link)
    await bridge.start()
    await eventually(lambda: bridge.counters.worlds_applied >= 1, what="the world")
    return bridge, runtime


@pytest.fixture
async def ros2_bridge(
    db_url: str, zenoh_settings: ZenohSettings, sim: FakeSim
) -> AsyncIterator[Bridge]:
    """A bridge on the ROS 2 link (robot r1 takes TwistStamped, r2 Twist), with a world."""
    link = RobotLinkSettings(link="ros2", robots={"r1": RobotTopics(cmd_vel_type="twist_stamped")})
    bridge, runtime = await start_ros2_bridge(db_url, zenoh_settings, sim, link)
    sim.clock(10.0)
    await eventually(lambda: bridge.runtime.clock.now() == 10.0, what="the sim clock")
    try:
        yield bridge
    finally:
        await bridge.stop()
        await runtime.close()


def finite(values: list[float]) -> bool:
    return all(math.isfinite(v) for v in values)


__all__ = ["Robot", "battery_msg", "finite", "np", "odom_msg", "scan_msg", "start_ros2_bridge"]

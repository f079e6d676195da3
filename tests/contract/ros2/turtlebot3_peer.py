"""A TurtleBot3 played by an independent ROS 2 client: ``zenoh-ros2-sdk`` (PyPI), not the
project's own rmw_zenoh code. It publishes ``scan``, ``odom``, ``battery_state`` and ``/tf``
under ``/r1`` and obeys ``cmd_vel`` (a Twist) with a unicycle model and the firmware's 0.5 s
command timeout, stamping everything with the system clock (ROS time, no ``use_sim_time``).

The SDK downloads message definitions from GitHub by default; here it runs offline: each
definition it needs is written as a ``.msg`` file from rosbags' Jazzy store into a folder
given to its registry, and it computes the RIHS01 hashes from those itself.
"""

from __future__ import annotations

import math
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from common import ros2types
from pnav.run.stack_options import StackOptions

TYPES = (
    ros2types.LASER_SCAN,
    ros2types.ODOMETRY,
    ros2types.BATTERY_STATE,
    ros2types.TF_MESSAGE,
    ros2types.TWIST,
    ros2types.POSE_STAMPED,
)
RATE_HZ = 30.0
SCAN_EVERY = 6  # 5 Hz
BATTERY_EVERY = 30  # 1 Hz
CMD_TIMEOUT_S = 0.5


def write_definitions(folder: Path) -> None:
    """Every type of TYPES and what it uses, as ``<pkg>/msg/<Name>.msg``, from rosbags."""
    store = ros2types.store()
    for name in TYPES:
        subdefs: dict[str, tuple[str, str]] = {}
        text, _ = store.gendefhash(name, subdefs, ros_version=2)
        for typ, body in [(name, text), *((k, v[0]) for k, v in subdefs.items())]:
            pkg, kind, leaf = typ.split("/")
            path = folder / pkg / kind / f"{leaf}.msg"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(body)


class TurtleBot3:
    def __init__(self, router_port: int, x: float, y: float, yaw: float) -> None:
        # imported here: the SDK opens its one session on first use, with the environment
        from zenoh_ros2_sdk import (
            ROS2Publisher,
            ROS2Subscriber,
            get_message_class,
            get_registry,
            message_registry,
        )

        self._folder = tempfile.TemporaryDirectory(prefix="tb3-msgs-")
        write_definitions(Path(self._folder.name))
        # the SDK keeps one registry per process, on the first robot's folder (removed when
        # that robot closes): each robot starts its own
        message_registry._registry = None
        get_registry(self._folder.name)
        self.x, self.y, self.yaw = x, y, yaw
        self.v = self.w = 0.0
        self.last_cmd = 0.0
        self.commands = 0
        self._stop = threading.Event()

        def pub(topic: str, typ: str) -> Any:
            return ROS2Publisher(
                topic, typ, node_name="turtlebot3", router_port=router_port, domain_id=0
            )

        self.scan = pub("/r1/scan", ros2types.LASER_SCAN)
        self.odom = pub("/r1/odom", ros2types.ODOMETRY)
        self.battery = pub("/r1/battery_state", ros2types.BATTERY_STATE)
        self.tf = pub("/tf", ros2types.TF_MESSAGE)
        self.goal = pub("/goal_pose", ros2types.POSE_STAMPED)
        self.cmd = ROS2Subscriber(
            "/r1/cmd_vel",
            ros2types.TWIST,
            self._on_cmd,
            node_name="turtlebot3",
            router_port=router_port,
            domain_id=0,
        )
        self.M = {name: get_message_class(name) for name in _CLASSES}
        self._thread = threading.Thread(target=self._run, name="tb3", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        for entity in (self.scan, self.odom, self.battery, self.tf, self.goal, self.cmd):
            try:
                entity.close()
            except Exception:
                pass
        # the SDK's one session per process is on this robot's router: the next robot, in
        # another test, opens its own on its own router
        from zenoh_ros2_sdk.session import ZenohSession

        if ZenohSession._instance is not None:
            ZenohSession._instance.close()
        self._folder.cleanup()

    def _on_cmd(self, msg: Any) -> None:
        self.v, self.w = float(msg.linear.x), float(msg.angular.z)
        self.last_cmd = time.monotonic()
        self.commands += 1

    # -- messages ------------------------------------------------------------------------------
    def _header(self, now: float, frame: str) -> Any:
        sec = math.floor(now)
        stamp = self.M["builtin_interfaces/msg/Time"](sec=sec, nanosec=int((now - sec) * 1e9))
        return self.M["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def _vec(self, x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Any:
        return self.M["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)

    def _quat(self, yaw: float) -> Any:
        q = self.M["geometry_msgs/msg/Quaternion"]
        return q(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))

    def _pose(self, x: float, y: float, yaw: float) -> Any:
        point = self.M["geometry_msgs/msg/Point"](x=x, y=y, z=0.0)
        return self.M["geometry_msgs/msg/Pose"](position=point, orientation=self._quat(yaw))

    def send_goal(self, x: float, y: float) -> None:
        """As RViz's 2D Goal Pose does."""
        self.goal.publish(header=self._header(time.time(), "map"), pose=self._pose(x, y, 0.0))

    def _publish_odom(self, now: float) -> None:
        zeros = np.zeros(36, dtype=np.float64)
        twist = self.M["geometry_msgs/msg/Twist"](
            linear=self._vec(x=self.v), angular=self._vec(z=self.w)
        )
        self.odom.publish(
            header=self._header(now, "r1/odom"),
            child_frame_id="r1/base_footprint",
            pose=self.M["geometry_msgs/msg/PoseWithCovariance"](
                pose=self._pose(self.x, self.y, self.yaw), covariance=zeros
            ),
            twist=self.M["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=zeros),
        )
        transform = self.M["geometry_msgs/msg/Transform"](
            translation=self._vec(self.x, self.y), rotation=self._quat(self.yaw)
        )
        stamped = self.M["geometry_msgs/msg/TransformStamped"](
            header=self._header(now, "r1/odom"),
            child_frame_id="r1/base_footprint",
            transform=transform,
        )
        self.tf.publish(transforms=[stamped])

    def _publish_scan(self, now: float) -> None:
        # an empty room as the lidar sees it from anywhere near the middle: no return
        self.scan.publish(
            header=self._header(now, "r1/base_scan"),
            angle_min=0.0,
            angle_max=math.tau * 359 / 360,
            angle_increment=math.tau / 360,
            time_increment=0.0,
            scan_time=0.2,
            range_min=0.12,
            range_max=3.5,
            ranges=np.full(360, np.inf, dtype=np.float32),
            intensities=np.zeros(0, dtype=np.float32),
        )

    def _publish_battery(self, now: float) -> None:
        nan = math.nan
        self.battery.publish(
            header=self._header(now, "r1/base_footprint"),
            voltage=12.0,
            temperature=nan,
            current=-0.5,
            charge=1.2,
            capacity=1.8,
            design_capacity=1.8,
            percentage=1.2 / 1.8,
            power_supply_status=2,
            power_supply_health=0,
            power_supply_technology=3,
            present=True,
            cell_voltage=np.zeros(0, dtype=np.float32),
            cell_temperature=np.zeros(0, dtype=np.float32),
            location="",
            serial_number="",
        )

    # -- the loop --------------------------------------------------------------------------------
    def _run(self) -> None:
        dt, tick = 1.0 / RATE_HZ, 0
        while not self._stop.wait(dt):
            if time.monotonic() - self.last_cmd > CMD_TIMEOUT_S:
                self.v = self.w = 0.0  # the firmware's watchdog
            self.x += self.v * math.cos(self.yaw) * dt
            self.y += self.v * math.sin(self.yaw) * dt
            self.yaw = math.atan2(
                math.sin(self.yaw + self.w * dt), math.cos(self.yaw + self.w * dt)
            )
            now = time.time()
            self._publish_odom(now)
            if tick % SCAN_EVERY == 0:
                self._publish_scan(now)
            if tick % BATTERY_EVERY == 0:
                self._publish_battery(now)
            tick += 1


_CLASSES = (
    "builtin_interfaces/msg/Time",
    "std_msgs/msg/Header",
    "geometry_msgs/msg/Vector3",
    "geometry_msgs/msg/Quaternion",
    "geometry_msgs/msg/Point",
    "geometry_msgs/msg/Pose",
    "geometry_msgs/msg/Twist",
    "geometry_msgs/msg/PoseWithCovariance",
    "geometry_msgs/msg/TwistWithCovariance",
    "geometry_msgs/msg/Transform",
    "geometry_msgs/msg/TransformStamped",
)


def peer_stack_options(folder: Path) -> StackOptions:
    """A local stack on the open room that drives its robots over the ROS 2 link, with no sim
    of its own (what `pnav up --no-sim --robot-link ros2` sets): the peer is the robot."""
    link = folder / "link.yaml"
    link.write_text("clock: ros\nuse_sim_time: false\n")
    return StackOptions(
        world="open_room",
        zenoh_port=None,
        extra_env={
            "PNAV_ROBOT_LINK": "ros2",
            "PNAV_ROS2_LINK_FILE": str(link),
            "PNAV_SIM_WORLD_ONLY": "1",
        },
    )

"""The sim as a ROS 2 robot (``--robot-link ros2``): its sensors and cmd_vel on rmw_zenoh.

One ROS 2 node, ``/pnav_sim``, on its own Zenoh session (``RobotLinkSettings``), publishes per
robot ``scan`` (sensor_msgs/LaserScan), ``odom`` (nav_msgs/Odometry), ``battery_state``
(sensor_msgs/BatteryState) and ``/tf`` (odom -> base_footprint), and subscribes ``cmd_vel``
(Twist or TwistStamped, as the robot-link file says), under each robot's namespace, as a
TurtleBot3 with rmw_zenoh would. Stamps are sim time (a ROS robot with ``use_sim_time``).
The world and collision events stay on the native wire: they are the sim's own (a real robot
has no collision message), and the bridge keeps listening to them there. So does the clock,
unless the robot-link file says ``clock: ros`` (with ``use_sim_time: true``): the sim then
publishes ROS ``/clock`` as Gazebo does, and the bridge turns it into ``pnav/sim/clock``.

The battery has no voltage in the sim; it is published at a nominal voltage
(``ros2types.NOMINAL_VOLTS``) with charge, capacity and current in A h and A, so the bridge
gets the sim's Wh and W back.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterable
from typing import Any, Final

import numpy as np
import numpy.typing as npt
import zenoh

from common import ros2types
from common.contract import keys
from common.contract import rmw_zenoh as rz
from common.robotlink import CLOCK_ROS, NATIVE, TWIST_STAMPED, RobotLinkSettings, RobotTopics
from common.ros2node import Publisher, Ros2Node, type_of_key

NODE_NAME: Final = "pnav_sim"
TOPICS: Final = (keys.SCAN, keys.ODOM, keys.BATTERY_MSG)

# robot, linear, angular (already checked finite), the attachment's sequence number (-1
# without one); or robot and what is wrong
OnCommand = Callable[[str, float, float, int], None]
OnBadCommand = Callable[[str, str], None]


def frame(namespace: str, name: str) -> str:
    """A robot's frame id: ``r1/odom`` under ``/r1``, ``odom`` with no namespace."""
    return f"{namespace.strip('/')}/{name}".strip("/")


def scan_msg(message: dict[str, Any], frame_id: str) -> Any:
    ranges = np.asarray(message["ranges"], dtype=np.float32)
    increment = float(message["angle_increment"])
    start = float(message["angle_min"])
    return laser_scan(
        message["stamp"],
        frame_id,
        (start, start + increment * (len(ranges) - 1), increment),
        (float(message["range_min"]), float(message["range_max"])),
        ranges,
    )


def laser_scan(
    stamp: float,
    frame_id: str,
    angles: tuple[float, float, float],
    limits: tuple[float, float],
    ranges: npt.NDArray[np.float32],
) -> Any:
    """A sensor_msgs/LaserScan of one sweep: ``angles`` (min, max, increment), ``limits``
    (range min, max); no timing, no intensities (the sim's lidar has none)."""
    (angle_min, angle_max, increment), (range_min, range_max) = angles, limits
    return ros2types.message(
        ros2types.LASER_SCAN,
        header=ros2types.header(stamp, frame_id),
        angle_min=angle_min,
        angle_max=angle_max,
        angle_increment=increment,
        time_increment=0.0,
        scan_time=0.0,
        range_min=range_min,
        range_max=range_max,
        ranges=ranges,
        intensities=np.zeros(0, dtype=np.float32),
    )


def _vector(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Any:
    return ros2types.message("geometry_msgs/msg/Vector3", x=x, y=y, z=z)


def odom_msg(message: dict[str, Any], odom_frame: str, base_frame: str) -> Any:
    point = ros2types.message("geometry_msgs/msg/Point", x=message["x"], y=message["y"], z=0.0)
    pose = ros2types.message(
        "geometry_msgs/msg/Pose", position=point, orientation=ros2types.quaternion(message["yaw"])
    )
    twist = ros2types.message(
        ros2types.TWIST, linear=_vector(x=message["linear"]), angular=_vector(z=message["angular"])
    )
    zeros = np.zeros(36, dtype=np.float64)
    return ros2types.message(
        ros2types.ODOMETRY,
        header=ros2types.header(message["stamp"], odom_frame),
        child_frame_id=base_frame,
        pose=ros2types.message("geometry_msgs/msg/PoseWithCovariance", pose=pose, covariance=zeros),
        twist=ros2types.message(
            "geometry_msgs/msg/TwistWithCovariance", twist=twist, covariance=zeros
        ),
    )


def battery_msg(message: dict[str, Any], frame_id: str) -> Any:
    return ros2types.battery_state(
        message["stamp"],
        frame_id,
        power_w=message["power_w"],
        energy_wh=message["energy_wh"],
        capacity_wh=message["capacity_wh"],
        percentage=message["percentage"],
        charging=bool(message["charging"]),
    )


def tf_msg(stamp: float, parent: str, child: str, message: dict[str, Any]) -> Any:
    transform = ros2types.message(
        "geometry_msgs/msg/Transform",
        translation=_vector(message["x"], message["y"]),
        rotation=ros2types.quaternion(message["yaw"]),
    )
    stamped = ros2types.message(
        "geometry_msgs/msg/TransformStamped",
        header=ros2types.header(stamp, parent),
        child_frame_id=child,
        transform=transform,
    )
    return ros2types.message(ros2types.TF_MESSAGE, transforms=[stamped])


class Ros2Wire:
    def __init__(
        self,
        settings: RobotLinkSettings,
        session: zenoh.Session,
        robots: Iterable[str],
        on_command: OnCommand,
        on_bad_command: OnBadCommand,
    ) -> None:
        self.settings = settings
        self.node = Ros2Node(session, settings.domain_id, NODE_NAME)
        self.on_command = on_command
        self.on_bad_command = on_bad_command
        self._publishers: dict[tuple[str, str], Publisher] = {}
        self._topics: dict[str, RobotTopics] = {}
        self._cmd_type: dict[str, ros2types.RosType] = {}
        self._tf = self.node.publisher("/tf", ros2types.TF_MESSAGE)
        self._clock = (
            self.node.publisher("/clock", ros2types.CLOCK, rz.QoS(reliability=2, depth=1))
            if settings.clock == CLOCK_ROS
            else None
        )
        for robot in robots:
            self._declare(robot)

    def _declare(self, robot: str) -> None:
        topics = self._topics[robot] = self.settings.topics(robot)
        ns = topics.resolved_namespace(robot)
        names = {
            keys.SCAN: topics.scan,
            keys.ODOM: topics.odom,
            keys.BATTERY_MSG: topics.battery_state,
        }
        types = {
            keys.SCAN: ros2types.LASER_SCAN,
            keys.ODOM: ros2types.ODOMETRY,
            keys.BATTERY_MSG: ros2types.BATTERY_STATE,
        }
        for topic in TOPICS:
            qos = rz.SENSOR_DATA if topic == keys.SCAN else rz.RELIABLE
            name = rz.fully_qualified(ns, names[topic])
            self._publishers[(robot, topic)] = self.node.publisher(name, types[topic], qos)
        kind = ros2types.TWIST_STAMPED if topics.cmd_vel_type == TWIST_STAMPED else ros2types.TWIST
        self._cmd_type[robot] = ros2types.ros_type(kind)
        handler = functools.partial(self._on_cmd_vel, robot)
        self.node.subscription(rz.fully_qualified(ns, topics.cmd_vel), kind, handler)

    def publish(self, robot: str, topic: str, message: dict[str, Any]) -> int:
        """Publish a reading; returns its attachment's sequence number (what the bridge
        stores as the row's ``seq``)."""
        topics = self._topics[robot]
        ns = topics.resolved_namespace(robot)
        odom_frame, base = frame(ns, topics.odom_frame), frame(ns, topics.base_frame)
        if topic == keys.SCAN:
            msg = scan_msg(message, frame(ns, "base_scan"))
        elif topic == keys.ODOM:
            msg = odom_msg(message, odom_frame, base)
            self._tf.put(tf_msg(message["stamp"], odom_frame, base, message))
        else:
            msg = battery_msg(message, base)
        return self._publishers[(robot, topic)].put(msg)

    def publish_clock(self, stamp: float) -> bool:
        """Publish sim time as ROS ``/clock`` if the link says so (``clock: ros``)."""
        if self._clock is None:
            return False
        self._clock.put(ros2types.message(ros2types.CLOCK, clock=ros2types.time_msg(stamp)))
        return True

    def _on_cmd_vel(self, robot: str, key: str, payload: bytes, att: bytes | None) -> None:
        """On Zenoh's thread: a Twist (or TwistStamped) -> the robot's command."""
        expected = self._cmd_type[robot]
        try:
            if type_of_key(key) != (expected.dds, expected.hash):
                raise ValueError(f"{key.rsplit('/', 2)[1]} is not {expected.name}")
            msg = ros2types.decode(expected.name, payload)
        except Exception as exc:
            self.on_bad_command(robot, f"not a {expected.name}: {str(exc)[:120]}")
            return
        twist = msg.twist if expected.name == ros2types.TWIST_STAMPED else msg
        linear, angular = float(twist.linear.x), float(twist.angular.z)
        if not (math.isfinite(linear) and math.isfinite(angular)):
            self.on_bad_command(robot, f"cmd_vel not finite: {linear}, {angular}")
            return
        self.on_command(robot, linear, angular, _sequence(att))

    def close(self) -> None:
        self.node.close()


def _sequence(att: bytes | None) -> int:
    """The attachment's sequence number, -1 without a readable one (it only labels the trace)."""
    if att is None:
        return -1
    try:
        return rz.Attachment.decode(att).sequence_number
    except ValueError:
        return -1


def make_wire(
    settings: RobotLinkSettings | None,
    session: zenoh.Session,
    robots: Iterable[str],
    on_command: OnCommand,
    on_bad_command: OnBadCommand,
    *,
    paced: bool,
) -> Ros2Wire | None:
    """The sim's ROS 2 wire, or None on the native link; ``paced`` (lockstep or --max-lag)
    is refused with ROS 2: neither counts nor gates what crosses it."""
    if settings is None or settings.link == NATIVE:
        return None
    if paced:
        raise ValueError("--lockstep and --max-lag run only on the native robot link")
    if settings.clock == CLOCK_ROS and not settings.use_sim_time:
        # the sim stamps in sim time: the bridge's wall clock would leave every reading stale
        raise ValueError("the sim with clock: ros needs use_sim_time: true (its /clock)")
    return Ros2Wire(settings, session, robots, on_command, on_bad_command)

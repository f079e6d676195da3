"""The bridge's ROS 2 robot link: the robots' sensors and cmd_vel on the ROS 2 graph.

Its own Zenoh session (``RobotLinkSettings.session_settings``: the rmw_zenoh router, or the
stack's own router as the bridge) carries one ROS 2 node, ``/pnav_bridge``, announced with
rmw_zenoh's liveliness tokens. Per robot (namespace and names from the robot-link file) it
subscribes ``scan``, ``odom``, ``battery_state``, and ``/tf`` and ``/tf_static`` once, and
publishes ``cmd_vel`` (Twist or TwistStamped). Every sample is handed from Zenoh's thread to
the event loop and there:

1. counted (``messages_in["ros2/<topic>"]``) and, beyond ``MAX_RATE_HZ`` per robot and topic
   within one second, dropped (``too_fast``): a flood costs a counter, not the database;
2. refused if its key names another type (``wrong_type``) or another hash of the type
   (``wrong_type_hash``), or it is too large, or it is not CDR of the type (``bad_cdr``);
3. converted (:mod:`.ros2msgs`) into the body the sim would have sent and validated by the
   same parsers (:mod:`.messages`): NaN, ranges, beam counts, all as for the sim (a scan's
   NaN and infinite ranges first become what the contract's row means, REP 117).

What passes goes to ``on_record``, what fails to ``on_malformed`` (counted per topic and reason,
one log line per kind per period: the bridge's own path).
"""

from __future__ import annotations

import asyncio
import functools
import logging
import time
from collections import Counter
from collections.abc import Callable, Iterable
from typing import Any, Final

import zenoh

import services.bridge.ros2msgs as ros2msgs
import services.bridge.sensor_payloads as messages
from common import ros2types
from common.contract import keys
from common.contract import rmw_zenoh as rz
from common.robotlink import TWIST_STAMPED, RobotLinkSettings, RobotTopics
from common.ros2node import Publisher, Ros2Node, type_of_key
from common.trace import CMD_VEL, Tracer
from services.bridge.counters import Counters
from services.bridge.sensor_payloads import MalformedMessage, SensorRecord

logger = logging.getLogger("pnav.bridge.ros2")

NODE_NAME: Final = "pnav_bridge"
# samples per robot and topic in one second beyond which the rest of that second is dropped
MAX_RATE_HZ: Final = 500
# a CDR payload larger than this is refused before decoding (the native link's bound)
MAX_CDR_BYTES: Final = messages.MAX_PAYLOAD_BYTES

WRONG_TYPE_HASH: Final = "wrong_type_hash"
BAD_CDR: Final = "bad_cdr"
TOO_FAST: Final = "too_fast"

# our sensor topic -> (ROS 2 type, the RobotTopics field naming it, the QoS we ask for)
SENSORS: Final = {
    keys.SCAN: (ros2types.LASER_SCAN, "scan", rz.SENSOR_DATA),
    keys.ODOM: (ros2types.ODOMETRY, "odom", rz.RELIABLE),
    keys.BATTERY_MSG: (ros2types.BATTERY_STATE, "battery_state", rz.RELIABLE),
}
TF_TOPICS: Final = ("/tf", "/tf_static")
MAP_FRAME: Final = "map"

OnRecord = Callable[[SensorRecord], None]
OnMalformed = Callable[[str, str, str, str], None]  # topic, reason, detail, key


class Ros2Link:
    def __init__(
        self,
        settings: RobotLinkSettings,
        session: zenoh.Session,
        counters: Counters,
        on_record: OnRecord,
        on_malformed: OnMalformed,
        tracer: Tracer | None = None,
    ) -> None:
        self.settings = settings
        self.tracer = tracer
        self.session = session
        self.counters = counters
        self.on_record = on_record
        self.on_malformed = on_malformed
        self.node = Ros2Node(session, settings.domain_id, NODE_NAME)
        self.robots: dict[str, int] = {}  # robot -> lidar beams (the bridge's)
        self._declared: set[str] = set()
        self._cmd_vel: dict[str, Publisher] = {}
        self._expected: dict[tuple[str, str], tuple[str, str]] = {}  # (robot, topic) -> type
        self._seq: Counter[tuple[str, str]] = Counter()
        self._window: dict[tuple[str, str], tuple[int, int]] = {}  # -> (second, count)
        self.map_odom: dict[str, ros2msgs.MapOdom] = {}
        self._loop: asyncio.AbstractEventLoop | None = None

    def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        for topic in TF_TOPICS:
            qos = rz.LATCHED if topic == "/tf_static" else rz.RELIABLE
            self.node.subscription(
                topic, ros2types.TF_MESSAGE, functools.partial(self._from_zenoh, None, "tf"), qos
            )

    def ensure(self, robots: dict[str, int]) -> None:
        """Declare the subscriptions and the cmd_vel publisher of robots not seen before."""
        self.robots = robots
        for robot in sorted(set(robots) - self._declared):
            self._declared.add(robot)
            self._declare(robot, self.settings.topics(robot))

    def _declare(self, robot: str, topics: RobotTopics) -> None:
        ns = topics.resolved_namespace(robot)
        for topic, (type_name, field, qos) in SENSORS.items():
            name = rz.fully_qualified(ns, getattr(topics, field))
            handler = functools.partial(self._from_zenoh, robot, topic)
            self.node.subscription(name, type_name, handler, qos)
            t = ros2types.ros_type(type_name)
            self._expected[(robot, topic)] = (t.dds, t.hash)
        kind = ros2types.TWIST_STAMPED if topics.cmd_vel_type == TWIST_STAMPED else ros2types.TWIST
        self._cmd_vel[robot] = self.node.publisher(rz.fully_qualified(ns, topics.cmd_vel), kind)
        logger.info("ros2 robot %s: namespace %s, cmd_vel %s", robot, ns, kind)

    def close(self) -> None:
        self.node.close()
        if self.tracer is not None:
            self.tracer.close()

    # -- commands --------------------------------------------------------------------------
    def send_cmd_vel(
        self,
        robot: str,
        stamp: float,
        linear: float,
        angular: float,
        reliable: bool,
        command_id: int | None = None,
    ) -> None:
        publisher = self._cmd_vel.get(robot)
        if publisher is None:
            return  # not a robot of the link yet: its topics are declared with its row
        if publisher.type_name == ros2types.TWIST_STAMPED:
            frame = self.settings.topics(robot).base_frame
            msg = ros2msgs.twist_stamped(stamp, frame, linear, angular)
        else:
            msg = ros2msgs.twist(linear, angular)
        sent_ns = Tracer.now()
        wire = publisher.put(msg, reliable=reliable)
        if self.tracer is not None and command_id is not None:
            # a Twist has no room for the id: the trace says which attachment number carried it
            self.tracer.record(CMD_VEL, robot, command_id, wire, sent_ns)
            self.tracer.maybe_flush()

    # -- sensors ---------------------------------------------------------------------------
    def _from_zenoh(
        self, robot: str | None, topic: str, key: str, payload: bytes, att: bytes | None
    ) -> None:
        loop = self._loop
        if loop is None:
            return
        try:
            loop.call_soon_threadsafe(self._on_sample, robot, topic, key, payload, att)
        except RuntimeError:
            pass  # the loop is closed: shutting down

    def _on_sample(
        self, robot: str | None, topic: str, key: str, payload: bytes, att: bytes | None
    ) -> None:
        name = f"ros2/{topic}"
        self.counters.messages_in[name] += 1
        try:
            if self._flooded(robot or "_", topic):
                raise MalformedMessage(TOO_FAST, f"over {MAX_RATE_HZ} samples in one second")
            if robot is None:
                self._on_tf(key, payload)
                return
            record = self._parse(robot, topic, key, payload, att)
        except MalformedMessage as exc:
            self.on_malformed(name, exc.reason, exc.detail, key)
            return
        except Exception as exc:  # a bug in conversion: still never let it through
            self.on_malformed(name, "internal_error", repr(exc), key)
            return
        self.on_record(record)

    def _flooded(self, robot: str, topic: str) -> bool:
        second = int(time.monotonic())
        start, count = self._window.get((robot, topic), (second, 0))
        count = count + 1 if start == second else 1
        self._window[(robot, topic)] = (second, count)
        return count > MAX_RATE_HZ

    def _decode(self, type_name: str, expected: tuple[str, str], key: str, payload: bytes) -> Any:
        dds, type_hash = type_of_key(key)
        if dds != expected[0]:
            raise MalformedMessage(messages.WRONG_TYPE, f"{dds} where {expected[0]} is due")
        if type_hash != expected[1]:
            raise MalformedMessage(WRONG_TYPE_HASH, f"{type_hash} is not {expected[1]}")
        if len(payload) > MAX_CDR_BYTES:
            raise MalformedMessage(messages.TOO_LARGE, f"{len(payload)} bytes > {MAX_CDR_BYTES}")
        try:
            return ros2types.decode(type_name, payload)
        except Exception as exc:
            raise MalformedMessage(BAD_CDR, str(exc)[:160]) from None

    def _parse(
        self, robot: str, topic: str, key: str, payload: bytes, att: bytes | None
    ) -> SensorRecord:
        if robot not in self.robots:
            raise MalformedMessage(messages.UNKNOWN_ROBOT, f"robot {robot!r} has no row yet")
        type_name = SENSORS[topic][0]
        msg = self._decode(type_name, self._expected[(robot, topic)], key, payload)
        seq = self._sequence(robot, topic, att)
        if topic == keys.SCAN:
            beams: Counter[str] = Counter()
            body = ros2msgs.scan_body(msg, seq, beams)
            record = messages.parse_scan(robot, body, self.robots.get(robot))
            self.counters.ros2_beams.update(beams)  # of the scans stored only
            return record
        if topic == keys.ODOM:
            body = ros2msgs.odom_body(msg, seq, self.map_odom.get(robot))
            return messages.parse_odom(robot, body)
        return messages.parse_battery(robot, ros2msgs.battery_body(msg, seq))

    def _sequence(self, robot: str, topic: str, att: bytes | None) -> int:
        """The publisher's sequence number from the attachment; our own count without one."""
        if att is not None:
            try:
                seq = rz.Attachment.decode(att).sequence_number
                if 0 <= seq <= messages.MAX_SEQ:
                    return seq
            except ValueError:
                pass
        self._seq[(robot, topic)] += 1
        return self._seq[(robot, topic)]

    def _on_tf(self, key: str, payload: bytes) -> None:
        t = ros2types.ros_type(ros2types.TF_MESSAGE)
        msg = self._decode(t.name, (t.dds, t.hash), key, payload)
        for transform in msg.transforms:
            if transform.header.frame_id.strip("/") != MAP_FRAME:
                continue
            robot = self._robot_of_odom_frame(transform.child_frame_id.strip("/"))
            if robot is None:
                continue
            correction = ros2msgs.map_odom_of(transform)
            if correction is None:
                raise MalformedMessage(messages.NOT_FINITE, "map -> odom is not finite")
            self.map_odom[robot] = correction

    def _robot_of_odom_frame(self, frame: str) -> str | None:
        for robot in self._declared:
            topics = self.settings.topics(robot)
            ns = topics.resolved_namespace(robot).strip("/")
            if frame in (f"{ns}/{topics.odom_frame}".strip("/"), topics.odom_frame):
                return robot
        return None


def native_topics(link: str) -> Iterable[str]:
    """The native sensor topics the bridge still subscribes with ``link``: all of them
    natively; with ROS 2 only the sim's collision events (ROS 2 has no such message)."""
    return keys.SENSOR_TOPICS if link == "native" else (keys.COLLISION,)

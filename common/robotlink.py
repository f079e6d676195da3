"""Which wire the robots are on: the native one (msgpack on ``pnav/robot/...``) or ROS 2.

Read from the environment by the bridge and the sim alike (``pnav up --robot-link ros2`` sets
it for both), so the two sides of the robot link agree on every name:

- ``PNAV_ROBOT_LINK``: ``native`` (default) or ``ros2``;
- ``PNAV_ROS_DOMAIN_ID``: the ROS domain (ROS_DOMAIN_ID), default 0;
- ``PNAV_ROS2_CONNECT``: the rmw_zenoh router the ROS 2 session connects to
  (``tcp/localhost:7447`` is where ``ros2 run rmw_zenoh_cpp rmw_zenohd`` listens); empty (the
  default): the stack's own router, as the service itself (its user and password);
- ``PNAV_ROS2_LINK_FILE``: a robot-link file, per robot its namespace and topic names, and
  where the stack's clock comes from.

A robot-link file (YAML) names, per robot id, what differs from the defaults: a robot's
namespace is ``/<robot id>`` (Nav2's multi-robot namespacing), its topics ``scan``, ``odom``,
``battery_state``, ``cmd_vel`` (``twist`` or ``twist_stamped``), ``plan``, and its frames
``odom``, ``base_footprint``. ``default`` applies to every robot the file does not name::

    robots:
      r1: {namespace: "", cmd_vel_type: twist_stamped}   # a lone TurtleBot3 on Jazzy
    default: {cmd_vel_type: twist}
    clock: ros           # no pybullet sim: the bridge publishes pnav/sim/clock in ROS time
    use_sim_time: false  # ROS time is the system clock (true: ROS /clock)
    map: /map            # the map is a map server's OccupancyGrid, not the world's map file

``clock: sim`` (the default) leaves ``pnav/sim/clock`` to the pybullet sim, as ``pnav up``
runs it; ``clock: ros`` is a robot with no pybullet sim, whose stamps are ROS time.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Final

import yaml

from common.config import ZenohSettings
from common.contract import rmw_zenoh as rz
from common.errors import ConfigError

NATIVE: Final = "native"
ROS2: Final = "ros2"
LINKS: Final = (NATIVE, ROS2)
TWIST: Final = "twist"
TWIST_STAMPED: Final = "twist_stamped"
# who publishes pnav/sim/clock: the pybullet sim, or the bridge's ROS 2 link in ROS time
CLOCK_SIM: Final = "sim"
CLOCK_ROS: Final = "ros"
FILE_KEYS: Final = ("robots", "default", "clock", "use_sim_time", "map")


@dataclass(frozen=True)
class RobotTopics:
    namespace: str = ""  # "" means /<robot id>
    scan: str = "scan"
    odom: str = "odom"
    battery_state: str = "battery_state"
    cmd_vel: str = "cmd_vel"
    cmd_vel_type: str = TWIST
    plan: str = "plan"
    odom_frame: str = "odom"
    base_frame: str = "base_footprint"
    explicit_namespace: bool = False  # the file gave a namespace (possibly "/")

    def resolved_namespace(self, robot: str) -> str:
        return rz.namespace_of(self.namespace if self.explicit_namespace else f"/{robot}")


_FIELDS: Final = (
    "namespace",
    "scan",
    "odom",
    "battery_state",
    "cmd_vel",
    "cmd_vel_type",
    "plan",
    "odom_frame",
    "base_frame",
)


def _topics(base: RobotTopics, body: Any, where: str) -> RobotTopics:
    if body is None:
        return base
    if not isinstance(body, Mapping):
        raise ConfigError(f"{where} must be a map")
    unknown = set(body) - set(_FIELDS)
    if unknown:
        raise ConfigError(f"{where}: unknown keys {sorted(unknown)} (known: {list(_FIELDS)})")
    values: dict[str, Any] = {k: str(v if v is not None else "") for k, v in body.items()}
    topics = replace(base, **values)
    if "namespace" in body:
        topics = replace(topics, explicit_namespace=True)
    if topics.cmd_vel_type not in (TWIST, TWIST_STAMPED):
        raise ConfigError(f"{where}: cmd_vel_type must be {TWIST} or {TWIST_STAMPED}")
    try:
        rz.namespace_of(topics.namespace or "/")
        for name in (topics.scan, topics.odom, topics.battery_state, topics.cmd_vel, topics.plan):
            rz.fully_qualified("/", name)
    except ValueError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    return topics


@dataclass(frozen=True)
class RobotLinkSettings:
    link: str = NATIVE
    domain_id: int = 0
    connect: str = ""
    default: RobotTopics = field(default_factory=RobotTopics)
    robots: Mapping[str, RobotTopics] = field(default_factory=dict)
    clock: str = CLOCK_SIM
    use_sim_time: bool = False  # with clock ros: ROS time is /clock, else the system clock
    # a nav_msgs/OccupancyGrid topic (``/map``) whose grid is the world's map; "": the map file
    map_topic: str = ""

    @property
    def bridge_clock(self) -> bool:
        """The bridge publishes the stack's clock (no pybullet sim on the ROS 2 link)."""
        return self.link == ROS2 and self.clock == CLOCK_ROS

    def topics(self, robot: str) -> RobotTopics:
        return self.robots.get(robot, self.default)

    def session_settings(self, own: ZenohSettings) -> ZenohSettings:
        """The ROS 2 session's: a client of the given rmw_zenoh router, or, with none given,
        of the stack's own router as the service itself (its user and password)."""
        if not self.connect:
            return own
        return ZenohSettings(mode="client", connect=(self.connect,), data_queue=own.data_queue)

    @classmethod
    def from_env(cls, env: Mapping[str, str] | None = None) -> RobotLinkSettings:
        env = os.environ if env is None else env
        link = env.get("PNAV_ROBOT_LINK", "").strip().lower() or NATIVE
        if link not in LINKS:
            raise ConfigError(f"PNAV_ROBOT_LINK={link!r} must be one of {', '.join(LINKS)}")
        raw = env.get("PNAV_ROS_DOMAIN_ID", "").strip() or "0"
        try:
            domain = rz.check_domain(int(raw))
        except ValueError:
            raise ConfigError(
                f"PNAV_ROS_DOMAIN_ID={raw!r} must be 0 to {rz.MAX_DOMAIN_ID}"
            ) from None
        path = env.get("PNAV_ROS2_LINK_FILE", "").strip()
        connect = env.get("PNAV_ROS2_CONNECT", "").strip()
        settings = cls(link, domain, connect)
        return settings if not path else load_link_file(Path(path), settings)


def load_link_file(path: Path, base: RobotLinkSettings | None = None) -> RobotLinkSettings:
    """``base`` (the defaults if None) with what the robot-link file at ``path`` says."""
    try:
        body = yaml.safe_load(path.read_text()) or {}
    except (OSError, yaml.YAMLError) as exc:
        raise ConfigError(f"robot-link file {path}: {exc}") from None
    if not isinstance(body, Mapping) or set(body) - set(FILE_KEYS):
        raise ConfigError(f"robot-link file {path}: a map of {', '.join(FILE_KEYS)}")
    clock = body.get("clock", CLOCK_SIM)
    if clock not in (CLOCK_SIM, CLOCK_ROS):
        raise ConfigError(f"{path}: clock must be {CLOCK_SIM} or {CLOCK_ROS}, not {clock!r}")
    use_sim_time = body.get("use_sim_time", False)
    if not isinstance(use_sim_time, bool):
        raise ConfigError(f"{path}: use_sim_time must be true or false")
    map_topic = str(body.get("map") or "")
    try:
        if map_topic:
            rz.fully_qualified("/", map_topic)
    except ValueError as exc:
        raise ConfigError(f"{path}: map: {exc}") from None
    default = _topics(RobotTopics(), body.get("default"), f"{path}: default")
    robots_body = body.get("robots") or {}
    if not isinstance(robots_body, Mapping):
        raise ConfigError(f"{path}: robots must be a map of robot id -> topics")
    robots = {
        str(robot): _topics(default, topics, f"{path}: robots.{robot}")
        for robot, topics in robots_body.items()
    }
    return replace(
        base or RobotLinkSettings(),
        default=default,
        robots=robots,
        clock=clock,
        use_sim_time=use_sim_time,
        map_topic=map_topic,
    )

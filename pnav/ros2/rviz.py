"""What RViz sends and shows, on the ROS 2 graph: 2D Goal Pose in, each robot's plan out.

One ROS 2 node, ``/pnav_rviz``, acting for **people** (Postgres role ``pnav_user``): a goal is
people's row (CONTRACT.md, *Roles*), so RViz's 2D Goal Pose is written as ``pnav goal``
writes it (:func:`common.contract.people.set_goal`), by this process, and the bridge gains no
write it did not have. It reads the robot-link file the bridge reads (namespaces, ``plan``).

- ``/goal_pose`` and each robot's ``<ns>/goal_pose`` (geometry_msgs/msg/PoseStamped, in the
  ``map`` frame; RViz publishes its tool's pose there) -> the robot's goal: its active goal
  superseded, the new one at (x, y) with the default tolerance and the arrow's heading.
  ``/goal_pose`` is the goal of the robot with the empty namespace, or of the only robot;
  with several robots and none un-namespaced it is refused (publish on ``<ns>/goal_pose``).
- each ``planned_path`` row (its notification's image, or the row read back) -> a
  nav_msgs/msg/Path on ``<ns>/plan`` in the ``map`` frame, stamped with the row's stamp; each
  pose heads towards the next waypoint. An empty row is an empty Path (no path in force), as
  Nav2's planner clears RViz's display.
- Nav2's NavigateToPose and NavigateThroughPoses actions, per robot (nav2actions.py).

A goal that cannot be a goal row is refused and counted (``refused[reason]``), logged.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import math
from collections import Counter
from collections.abc import Mapping
from typing import Any, Final

import zenoh

from common import bus, ros2types
from common.contract import keys, limits, people
from common.contract import rmw_zenoh as rz
from common.errors import ContractError
from common.robotlink import RobotLinkSettings
from common.ros2node import Publisher, Ros2Node, type_of_key
from common.runtime import Runtime
from pnav.ros2.nav2actions import (
    MAP_FRAME,
    OUT_OF_RANGE,
    Nav2Actions,
    Refused,
    goal_yaw,
    in_map_frame,
)

logger = logging.getLogger("pnav.ros2.rviz")

NODE_NAME: Final = "pnav_rviz"
GOAL_TOPIC: Final = "goal_pose"
ROBOT_RELOAD_S: Final = 2.0
MAX_PAYLOAD: Final = 4096  # a PoseStamped is under 100 bytes with a sane frame id

# reasons a goal pose is refused, beside Nav2Actions' (a frame, a value out of range)
WRONG_TYPE: Final = "wrong_type"
BAD_CDR: Final = "bad_cdr"
NO_ROBOT: Final = "no_robot"

NEWEST_PATH_SQL: Final = (
    f"SELECT id, robot_id, stamp, xs, ys FROM {keys.PLANNED_PATH} "
    "WHERE robot_id = $1 ORDER BY id DESC LIMIT 1"
)


class RvizLink:
    def __init__(
        self, runtime: Runtime, settings: RobotLinkSettings, ros_session: zenoh.Session
    ) -> None:
        self.runtime = runtime
        self.settings = settings
        self.node = Ros2Node(ros_session, settings.domain_id, NODE_NAME)
        self.nav = Nav2Actions(runtime, self.node)  # Nav2's actions, per robot
        self.robots: dict[str, str] = {}  # robot -> resolved namespace
        self.plans: dict[str, Publisher] = {}
        self.goals_set = 0
        self.plans_out = 0
        self.refused: Counter[str] = Counter()
        self._pose = ros2types.ros_type(ros2types.POSE_STAMPED)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._subscriber: Any = None
        self._tasks: list[asyncio.Task[None]] = []
        self._pending: set[asyncio.Task[None]] = set()  # goals and plans under way

    async def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        await self._load_robots()
        self.node.subscription(
            "/" + GOAL_TOPIC, ros2types.POSE_STAMPED, functools.partial(self._from_zenoh, None)
        )
        self._subscriber = bus.subscribe(
            self.runtime.zenoh, keys.notify_watch(keys.PLANNED_PATH), self._on_path_note
        )
        self._tasks.append(asyncio.create_task(self._reload_loop(), name="rviz-robots"))

    def _spawn(self, coro: Any) -> None:
        task: asyncio.Task[None] = asyncio.ensure_future(coro)
        self._pending.add(task)
        task.add_done_callback(self._done)

    def _done(self, task: asyncio.Task[None]) -> None:
        self._pending.discard(task)
        if not task.cancelled() and task.exception() is not None:
            logger.warning("ROS 2 goal or plan failed: %r", task.exception())

    async def close(self) -> None:
        for task in [*self._tasks, *self._pending]:
            task.cancel()
        for task in [*self._tasks, *self._pending]:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        if self._subscriber is not None:
            with contextlib.suppress(Exception):
                self._subscriber.undeclare()
        await self.nav.close()
        self.node.close()

    async def run(self, stop: asyncio.Event) -> None:
        await self.start()
        try:
            await stop.wait()
        finally:
            await self.close()

    # -- robots ------------------------------------------------------------------------------
    async def _reload_loop(self) -> None:
        while True:
            await asyncio.sleep(ROBOT_RELOAD_S)
            try:
                await self._load_robots()
            except Exception as exc:
                logger.warning("robot table read failed: %s", exc)

    async def _load_robots(self) -> None:
        rows = await self.runtime.database.pool.fetch(f"SELECT robot_id FROM {keys.ROBOT}")
        for (robot,) in rows:
            if robot not in self.robots:
                self._declare(robot)

    def _declare(self, robot: str) -> None:
        topics = self.settings.topics(robot)
        ns = self.robots[robot] = topics.resolved_namespace(robot)
        if ns != "/":  # under the empty namespace its goal_pose is /goal_pose, heard already
            name = rz.fully_qualified(ns, GOAL_TOPIC)
            handler = functools.partial(self._from_zenoh, robot)
            self.node.subscription(name, ros2types.POSE_STAMPED, handler)
        self.plans[robot] = self.node.publisher(
            rz.fully_qualified(ns, topics.plan), ros2types.PATH, rz.RELIABLE
        )
        self.nav.declare(robot, ns)

    # -- goals -------------------------------------------------------------------------------
    def _from_zenoh(self, robot: str | None, key: str, payload: bytes, att: bytes | None) -> None:
        loop = self._loop
        if loop is None:
            return
        with contextlib.suppress(RuntimeError):  # the loop is closed: shutting down
            loop.call_soon_threadsafe(lambda: self._spawn(self._on_goal_pose(robot, key, payload)))

    async def _on_goal_pose(self, robot: str | None, key: str, payload: bytes) -> None:
        try:
            target, x, y, yaw = self._goal(robot, key, payload)
            limits.check_goal(x, y, None)
        except Refused as exc:
            self._refuse(exc.reason, str(exc), key)
            return
        except ContractError as exc:
            self._refuse(OUT_OF_RANGE, str(exc), key)
            return
        goal_id = await people.set_goal(self.runtime.database, target, x, y, None, yaw=yaw)
        self.goals_set += 1
        heading = "any heading" if yaw is None else f"yaw {yaw:.3f} rad"
        logger.info(
            "goal %d for %s at (%.3f, %.3f), %s, from %s", goal_id, target, x, y, heading, key
        )

    def _goal(
        self, robot: str | None, key: str, payload: bytes
    ) -> tuple[str, float, float, float | None]:
        if type_of_key(key) != (self._pose.dds, self._pose.hash):
            raise Refused(WRONG_TYPE, f"{key.rsplit('/', 2)[1]} is not a PoseStamped")
        if len(payload) > MAX_PAYLOAD:
            raise Refused(BAD_CDR, f"{len(payload)} bytes")
        try:
            msg = ros2types.decode(ros2types.POSE_STAMPED, payload)
        except Exception as exc:
            raise Refused(BAD_CDR, str(exc)[:160]) from None
        in_map_frame(msg)
        target = robot if robot is not None else self._robot_of_global()
        return target, float(msg.pose.position.x), float(msg.pose.position.y), goal_yaw(msg.pose)

    def _robot_of_global(self) -> str:
        """The robot ``/goal_pose`` is for: the un-namespaced one, or the only one."""
        bare = [r for r, ns in self.robots.items() if ns == "/"]
        if len(bare) == 1:
            return bare[0]
        if len(self.robots) == 1:
            return next(iter(self.robots))
        raise Refused(
            NO_ROBOT,
            f"/{GOAL_TOPIC} with {len(self.robots)} robots and none un-namespaced: "
            f"publish on <namespace>/{GOAL_TOPIC}",
        )

    def _refuse(self, reason: str, detail: str, key: str) -> None:
        self.refused[reason] += 1
        logger.warning("goal pose refused (%s): %s [%s]", reason, detail[:200], key[:120])

    # -- plans -------------------------------------------------------------------------------
    def _on_path_note(self, key: str, payload: bytes) -> None:
        note = bus.Notification.decode(key, payload)
        if note.robot is None:
            return
        if note.row is not None:
            self._publish_plan(note.robot, note.row)
            return
        self._spawn(self._read_plan(note.robot))

    async def _read_plan(self, robot: str) -> None:
        row = await self.runtime.database.pool.fetchrow(NEWEST_PATH_SQL, robot)
        if row is not None:
            self._publish_plan(robot, dict(row))

    def _publish_plan(self, robot: str, row: Mapping[str, Any]) -> None:
        publisher = self.plans.get(robot)
        if publisher is None:
            return  # declared with the robot's row, within ROBOT_RELOAD_S
        try:
            msg = path_msg(float(row["stamp"]), list(row["xs"] or []), list(row["ys"] or []))
        except (KeyError, TypeError, ValueError) as exc:
            logger.warning("planned_path row %s not published: %s", row.get("id"), exc)
            return
        publisher.put(msg, reliable=True)
        self.plans_out += 1


def path_msg(stamp: float, xs: list[float], ys: list[float]) -> Any:
    """A nav_msgs/Path in the map frame through the waypoints, each heading to the next."""
    if len(xs) != len(ys):
        raise ValueError(f"{len(xs)} xs and {len(ys)} ys")
    header = ros2types.header(max(stamp, 0.0), MAP_FRAME)
    poses = []
    yaw = 0.0
    for i, (x, y) in enumerate(zip(xs, ys, strict=True)):
        if i + 1 < len(xs):
            yaw = math.atan2(ys[i + 1] - y, xs[i + 1] - x)
        point = ros2types.message("geometry_msgs/msg/Point", x=float(x), y=float(y), z=0.0)
        pose = ros2types.message(
            "geometry_msgs/msg/Pose", position=point, orientation=ros2types.quaternion(yaw)
        )
        poses.append(ros2types.message(ros2types.POSE_STAMPED, header=header, pose=pose))
    return ros2types.message(ros2types.PATH, header=header, poses=poses)

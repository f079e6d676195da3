"""Nav2's NavigateToPose and NavigateThroughPoses, served for each robot on the ROS 2 graph.

Code written against Nav2 (Simple Commander's ``goToPose`` and ``goThroughPoses``, a fleet
manager's action client) sends its goals to ``<ns>/navigate_to_pose`` and
``<ns>/navigate_through_poses``; the ``rviz`` process serves both per robot
(:mod:`common.ros2action`), acting for people as it does for RViz's goal poses:

- a goal -> the robot's goal row, as ``pnav goal`` writes it (:func:`people.set_goal`): the
  pose, with its heading; the poses of NavigateThroughPoses -> a route, every pose but the
  last a waypoint driven through (its heading not kept: one would halt the robot there).
  A goal the goal tables would refuse, not in the ``map`` frame, or with an orientation
  that is not finite is refused (``accepted`` false), counted and logged.
- feedback twice a second, from the rows: ``current_pose`` (the newest odometry),
  ``distance_remaining`` (along the planned path to its target, then straight through the
  poses still pending), ``navigation_time``, ``estimated_time_remaining`` (distance over the
  current speed), ``number_of_poses_remaining`` (the route's pending poses, the goal's own
  included). ``number_of_recoveries`` stays 0: the rows do not count recoveries.
- the result when the goal row ends: ``reached`` -> SUCCEEDED; ``failed`` -> ABORTED with
  error code UNKNOWN (9000) and the row's reason; ``cancelled`` after the client's cancel ->
  CANCELED; superseded or cancelled by anyone else (``pnav goal``, RViz, the dashboard, a
  newer action goal) -> ABORTED, the reason saying so.
- a cancel -> :func:`people.cancel_goal` of the robot's goal, if it is still this one.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import math
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Final

from common import ros2types
from common.contract import keys, people
from common.contract import rmw_zenoh as rz
from common.errors import ContractError
from common.ros2action import ABORTED, CANCELED, SUCCEEDED, ActionServer
from common.ros2interfaces import GET_STATE, NAVIGATE_THROUGH_POSES, NAVIGATE_TO_POSE
from common.ros2node import Ros2Node, ServiceCall
from common.runtime import Runtime

logger = logging.getLogger("pnav.ros2.nav2")

TO_POSE: Final = "navigate_to_pose"
NAVIGATOR_STATE: Final = "bt_navigator/get_state"  # lifecycle_msgs' GetState, Nav2's navigator
ACTIVE: Final = 3  # lifecycle_msgs/msg/State PRIMARY_STATE_ACTIVE
THROUGH_POSES: Final = "navigate_through_poses"
MAP_FRAME: Final = "map"
FEEDBACK_S: Final = 0.5
MOVING_MPS: Final = 0.05  # slower than this, no time remaining is estimated
# nav2_msgs' result error codes (Jazzy)
NONE: Final = 0
UNKNOWN: Final = 9000

GOAL_ROW_SQL: Final = f"SELECT status, reason FROM {keys.GOAL} WHERE id = $1"
ODOMETRY_SQL: Final = (
    f"SELECT stamp, x, y, yaw, linear_mps FROM {keys.ODOMETRY} "
    "WHERE robot_id = $1 ORDER BY id DESC LIMIT 1"
)
PATH_SQL: Final = (
    f"SELECT xs, ys, target_x, target_y FROM {keys.PLANNED_PATH} "
    "WHERE robot_id = $1 AND goal_id = $2 ORDER BY id DESC LIMIT 1"
)
PENDING_SQL: Final = (
    f"SELECT x, y FROM {keys.GOAL_WAYPOINT} WHERE goal_id = $1 AND status = 'pending' ORDER BY seq"
)

Point = tuple[float, float]


# reasons a goal is refused (the ``refused`` counters' keys); rviz.py refuses a goal pose
# for the same reasons, and for its own
FRAME: Final = "frame"
OUT_OF_RANGE: Final = "out_of_range"
NO_POSES: Final = "no_poses"


class Refused(Exception):
    """A goal refused for ``reason``; the message says what was wrong with it."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(detail)
        self.reason = reason


@dataclass
class Tracked:
    """An action goal under way: the server it came to, and the goal row it became."""

    server: ActionServer
    goal_id: bytes
    row: int
    goal: Point
    through: bool
    started: float  # monotonic
    canceling: bool = False


class Nav2Actions:
    def __init__(self, runtime: Runtime, node: Ros2Node) -> None:
        self.runtime = runtime
        self.node = node
        self.servers: dict[str, list[ActionServer]] = {}
        self.current: dict[str, Tracked] = {}
        self.refused: Counter[str] = Counter()
        self.accepted = 0
        self.ended: Counter[int] = Counter()  # per GoalStatus
        self._ticker: asyncio.Task[None] | None = None

    def declare(self, robot: str, namespace: str) -> None:
        """Serve both actions under the robot's namespace (call on the loop)."""
        self.servers[robot] = [
            ActionServer(
                self.node,
                rz.fully_qualified(namespace, name),
                kind,
                on_goal=functools.partial(self._on_goal, robot, through),
                on_cancel=functools.partial(self._on_cancel, robot),
            )
            for name, kind, through in (
                (TO_POSE, NAVIGATE_TO_POSE, False),
                (THROUGH_POSES, NAVIGATE_THROUGH_POSES, True),
            )
        ]
        self.node.service(rz.fully_qualified(namespace, NAVIGATOR_STATE), GET_STATE, _active)
        if self._ticker is None:
            self._ticker = asyncio.create_task(self._tick_loop(), name="nav2-feedback")

    async def close(self) -> None:
        if self._ticker is not None:
            self._ticker.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._ticker
        for servers in self.servers.values():
            for server in servers:
                await server.close()

    # -- goals ---------------------------------------------------------------------------------
    async def _on_goal(self, robot: str, through: bool, goal_id: bytes, goal: Any) -> bool:
        server = self.servers[robot][1 if through else 0]
        try:
            poses = [pose_of(p) for p in goal.poses] if through else [pose_of(goal.pose)]
            if not poses:
                raise Refused(NO_POSES, "NavigateThroughPoses with no pose")
            *ahead, last = poses
            # Nav2 drives through every pose but the last without stopping; a waypoint with a
            # heading would halt the robot there (PLANNER.md), so only the last keeps its own
            waypoints = [people.Pose(p.x, p.y) for p in ahead]
            people.check_route(last, waypoints)
        except Refused as exc:
            return self._refuse(robot, exc.reason, str(exc))
        except ContractError as exc:
            return self._refuse(robot, OUT_OF_RANGE, str(exc))
        row = await people.set_goal(
            self.runtime.database, robot, last.x, last.y, None, yaw=last.yaw, waypoints=waypoints
        )
        self.accepted += 1
        old = self.current.get(robot)
        self.current[robot] = Tracked(
            server, goal_id, row, (last.x, last.y), through, time.monotonic()
        )
        if old is not None:  # a newer goal preempts: Nav2 aborts the one it replaces
            self._end(old, ABORTED, UNKNOWN, "preempted by a newer goal")
        logger.info(
            "%s goal %s for %s: goal row %d, %d pose(s)",
            "NavigateThroughPoses" if through else "NavigateToPose",
            goal_id.hex(),
            robot,
            row,
            len(poses),
        )
        return True

    def _refuse(self, robot: str, reason: str, detail: str) -> bool:
        self.refused[reason] += 1
        logger.warning("navigation goal for %s refused (%s): %s", robot, reason, detail[:200])
        return False

    async def _on_cancel(self, robot: str, goal_id: bytes) -> None:
        tracked = self.current.get(robot)
        if tracked is None or tracked.goal_id != goal_id:
            return
        tracked.canceling = True
        row = await self.runtime.database.pool.fetchrow(GOAL_ROW_SQL, tracked.row)
        if row is not None and row["status"] == "active":
            cancelled = await people.cancel_goal(self.runtime.database, robot)
            if cancelled == tracked.row:
                self._end(tracked, CANCELED, NONE, "cancelled")
        # otherwise the row ended meanwhile: the next tick ends the goal as the row says

    def _end(self, tracked: Tracked, status: int, code: int, message: str) -> None:
        kind = tracked.server.type
        result = ros2types.message(f"{kind}_Result", error_code=code, error_msg=message)
        if tracked.server.finish(tracked.goal_id, status, result):
            self.ended[status] += 1
        for robot, now in list(self.current.items()):
            if now is tracked:
                del self.current[robot]

    # -- feedback and results --------------------------------------------------------------------
    async def _tick_loop(self) -> None:
        while True:
            await asyncio.sleep(FEEDBACK_S)
            for robot, tracked in list(self.current.items()):
                try:
                    await self._tick(robot, tracked)
                except Exception as exc:
                    logger.warning("navigation feedback for %s failed: %s", robot, exc)

    async def _tick(self, robot: str, tracked: Tracked) -> None:
        pool = self.runtime.database.pool
        row = await pool.fetchrow(GOAL_ROW_SQL, tracked.row)
        if self.current.get(robot) is not tracked:
            return  # preempted or cancelled while reading
        status, reason = (row["status"], row["reason"]) if row else ("gone", "goal row deleted")
        if status == "reached":
            self._end(tracked, SUCCEEDED, NONE, "")
        elif status == "cancelled" and tracked.canceling:
            self._end(tracked, CANCELED, NONE, "cancelled")
        elif status != "active":
            self._end(tracked, ABORTED, UNKNOWN, f"{status}: {reason or 'no reason given'}")
        else:
            await self._feedback(robot, tracked)

    async def _feedback(self, robot: str, tracked: Tracked) -> None:
        pool = self.runtime.database.pool
        odom = await pool.fetchrow(ODOMETRY_SQL, robot)
        if odom is None:
            return  # no pose yet: nothing to report
        path = await pool.fetchrow(PATH_SQL, robot, tracked.row)
        pending = [(r["x"], r["y"]) for r in await pool.fetch(PENDING_SQL, tracked.row)]
        poses = [*pending, tracked.goal]
        points: list[Point] = []
        target = None
        if path is not None:
            points = list(zip(path["xs"] or [], path["ys"] or [], strict=True))
            if path["target_x"] is not None and path["target_y"] is not None:
                target = (path["target_x"], path["target_y"])
        distance = distance_remaining((odom["x"], odom["y"]), points, target, poses)
        speed = abs(odom["linear_mps"])
        fields: dict[str, Any] = {
            "current_pose": ros2types.pose_stamped(
                odom["stamp"], MAP_FRAME, odom["x"], odom["y"], odom["yaw"]
            ),
            "navigation_time": ros2types.duration_msg(time.monotonic() - tracked.started),
            "estimated_time_remaining": ros2types.duration_msg(
                distance / speed if speed > MOVING_MPS else 0.0
            ),
            "number_of_recoveries": 0,
            "distance_remaining": distance,
        }
        if tracked.through:
            fields["number_of_poses_remaining"] = min(len(poses), 32767)
        kind = tracked.server.type
        tracked.server.feedback(tracked.goal_id, ros2types.message(f"{kind}_Feedback", **fields))


def pose_of(msg: Any) -> people.Pose:
    """A PoseStamped in the map frame -> a pose of the goal tables (values checked there)."""
    in_map_frame(msg)
    yaw = goal_yaw(msg.pose)
    return people.Pose(float(msg.pose.position.x), float(msg.pose.position.y), yaw)


def in_map_frame(msg: Any) -> None:
    """Refused unless the stamped message is in the map frame (or names none)."""
    frame = msg.header.frame_id.strip("/")
    if frame not in ("", MAP_FRAME):
        raise Refused(FRAME, f"frame {frame!r}: a goal is in the map frame")


def goal_yaw(pose: Any) -> float | None:
    """A goal's heading, the pose's orientation about z (RViz's arrow); None for an all-zero
    quaternion, which a client that sets only a position leaves: any heading. Refused if
    the quaternion is not finite."""
    q = pose.orientation
    parts = (float(q.x), float(q.y), float(q.z), float(q.w))
    if not all(math.isfinite(v) for v in parts):
        raise Refused(OUT_OF_RANGE, f"orientation not finite: {parts}")
    return ros2types.yaw_of(q) if any(parts) else None


def distance_remaining(
    robot: Point, path: Sequence[Point], target: Point | None, poses: Sequence[Point]
) -> float:
    """How far the robot still has to go: along the planned ``path`` from the point past the
    nearest one, to the path's end, then on to ``target`` (the pose of ``poses`` it leads
    to: the nearest one to it) and straight through the rest of ``poses``."""
    if not poses:
        return 0.0
    first = 0
    if target is not None:
        first = min(range(len(poses)), key=lambda i: math.dist(poses[i], target))
    if path:
        nearest = min(range(len(path)), key=lambda i: math.dist(path[i], robot))
        ahead = min(nearest + 1, len(path) - 1)
        total = math.dist(robot, path[ahead])
        total += sum(math.dist(a, b) for a, b in zip(path[ahead:], path[ahead + 1 :], strict=False))
        total += math.dist(path[-1], poses[first])
    else:
        total = math.dist(robot, poses[first])
    total += sum(math.dist(a, b) for a, b in zip(poses[first:], poses[first + 1 :], strict=False))
    return total


def _active(call: ServiceCall) -> None:
    """Simple Commander's waitUntilNav2Active asks the navigator's lifecycle state: the
    actions are served as long as this process runs, so it is active."""
    state = ros2types.message("lifecycle_msgs/msg/State", id=ACTIVE, label="active")
    name = f"{GET_STATE}_Response"
    call.reply(ros2types.encode(name, ros2types.message(name, current_state=state)))

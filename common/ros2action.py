"""A ROS 2 action server over rmw_zenoh, made of services and topics as rcl_action makes one.

ROS 2 has no action in its middleware: rcl_action builds one from three services and two
topics under ``<action>/_action/`` (rmw_zenoh keys each as any other service or topic):

| name | kind | type |
|---|---|---|
| ``send_goal`` | service | ``<pkg>/action/<Name>_SendGoal`` (goal id + goal -> accepted, stamp) |
| ``get_result`` | service | ``<pkg>/action/<Name>_GetResult`` (goal id -> status, result) |
| ``cancel_goal`` | service | ``action_msgs/srv/CancelGoal`` |
| ``feedback`` | topic | ``<pkg>/action/<Name>_FeedbackMessage`` (goal id + feedback) |
| ``status`` | topic, transient local, depth 1 | ``action_msgs/msg/GoalStatusArray`` |

``get_result`` is answered when the goal ends. So an rclpy or rclcpp ActionClient on
rmw_zenoh (Nav2's Simple Commander among them) finds the server by its liveliness tokens
(three ``SS``, two ``MP``) and talks to it unchanged.

What the goals mean is the owner's: ``on_goal(goal_id, goal)`` accepts (True) or refuses a
goal, ``on_cancel(goal_id)`` is told of a cancel request; the owner ends a goal with
:meth:`ActionServer.finish` and sends :meth:`ActionServer.feedback`. The server keeps the
states (an accepted goal executes at once, as Nav2's servers do), answers ``get_result``
once the goal ends, and keeps an ended goal's result for ``RESULT_KEEP_S`` (rcl_action's
default result timeout). It runs on the asyncio loop it was made on; Zenoh's threads only
hand requests over.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections import Counter
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any, Final

import numpy as np

from common import ros2types
from common.contract import rmw_zenoh as rz
from common.ros2interfaces import CANCEL_GOAL, GOAL_STATUS_ARRAY
from common.ros2node import Ros2Node, ServiceCall

logger = logging.getLogger("pnav.ros2.action")

# action_msgs/msg/GoalStatus
UNKNOWN, ACCEPTED, EXECUTING, CANCELING, SUCCEEDED, CANCELED, ABORTED = range(7)
ENDED: Final = frozenset((SUCCEEDED, CANCELED, ABORTED))
# action_msgs/srv/CancelGoal_Response.return_code
CANCEL_NONE, CANCEL_REJECTED, CANCEL_UNKNOWN_GOAL, CANCEL_ENDED = range(4)

RESULT_KEEP_S: Final = 900.0  # rcl_action's default result_timeout: 15 minutes
MAX_ENDED: Final = 100  # ended goals kept at most, the oldest forgotten first
MAX_REQUEST: Final = 1 << 20  # a request over 1 MiB is refused before decoding
STATUS_QOS: Final = rz.QoS(durability=rz.TRANSIENT_LOCAL, depth=1)  # rcl_action's status QoS

GoalCallback = Callable[[bytes, Any], Awaitable[bool]]
CancelCallback = Callable[[bytes], Awaitable[None]]


@dataclass
class GoalHandle:
    id: bytes  # the client's 16-byte UUID
    stamp: float  # accepted at, system clock (s)
    status: int = ACCEPTED
    decided: bool = False  # the owner accepted it (until then it is the owner's to learn of)
    result: Any = None
    ended_at: float | None = None
    waiting: list[ServiceCall] = field(default_factory=list)  # get_result calls to answer


class ActionServer:
    """One action ``name`` (relative to the node's namespace, or absolute) of ``action_type``
    (``pkg/action/Name``) on ``node``; make it on the asyncio loop it is to run on."""

    def __init__(
        self,
        node: Ros2Node,
        name: str,
        action_type: str,
        *,
        on_goal: GoalCallback,
        on_cancel: CancelCallback,
    ) -> None:
        self.node = node
        self.name = rz.fully_qualified(node.name.namespace, name)
        self.type = action_type
        self.on_goal = on_goal
        self.on_cancel = on_cancel
        self.goals: dict[bytes, GoalHandle] = {}
        self.refused: Counter[str] = Counter()  # requests not understood, per reason
        self._loop = asyncio.get_running_loop()
        self._pending: set[asyncio.Task[None]] = set()
        base = f"{self.name}/_action"
        self.feedback_out = node.publisher(f"{base}/feedback", f"{action_type}_FeedbackMessage")
        self.status_out = node.publisher(f"{base}/status", GOAL_STATUS_ARRAY, STATUS_QOS)
        node.service(f"{base}/send_goal", f"{action_type}_SendGoal", self._handover(self._goal))
        node.service(f"{base}/get_result", f"{action_type}_GetResult", self._handover(self._get))
        node.service(f"{base}/cancel_goal", CANCEL_GOAL, self._handover(self._cancel))

    # -- the owner's side ----------------------------------------------------------------------
    def feedback(self, goal_id: bytes, feedback: Any) -> None:
        """Publish ``feedback`` (``<Name>_Feedback``) of a goal still under way."""
        goal = self.goals.get(goal_id)
        if goal is None or goal.status in ENDED:
            return
        msg = ros2types.message(
            f"{self.type}_FeedbackMessage", goal_id=uuid_msg(goal_id), feedback=feedback
        )
        self.feedback_out.put(msg, reliable=True)

    def finish(self, goal_id: bytes, status: int, result: Any) -> bool:
        """End a goal (SUCCEEDED, CANCELED or ABORTED) with ``result`` (``<Name>_Result``):
        every get_result waiting for it is answered. False if it had ended already."""
        if status not in ENDED:
            raise ValueError(f"a goal ends SUCCEEDED, CANCELED or ABORTED, not {status}")
        goal = self.goals.get(goal_id)
        if goal is None or goal.status in ENDED:
            return False
        goal.status, goal.result, goal.ended_at = status, result, time.time()
        waiting, goal.waiting = goal.waiting, []
        for call in waiting:
            self._answer_result(call, goal)
        self._forget_old()
        self.publish_status()
        return True

    def publish_status(self) -> None:
        statuses = [
            ros2types.message(
                "action_msgs/msg/GoalStatus",
                goal_info=goal_info(g.id, g.stamp),
                status=g.status,
            )
            for g in sorted(self.goals.values(), key=lambda g: g.stamp)
        ]
        self.status_out.put(ros2types.message(GOAL_STATUS_ARRAY, status_list=statuses))

    async def close(self) -> None:
        for task in list(self._pending):
            task.cancel()
        for task in list(self._pending):
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        for goal in self.goals.values():
            for call in goal.waiting:
                call.drop()
            goal.waiting.clear()

    # -- requests ------------------------------------------------------------------------------
    def _handover(self, handler: Callable[[ServiceCall], Awaitable[None]]) -> Any:
        """A Zenoh-thread callback that runs ``handler(call)`` on the loop."""

        def on_call(call: ServiceCall) -> None:
            with contextlib.suppress(RuntimeError):  # the loop is closed: shutting down
                self._loop.call_soon_threadsafe(self._spawn, handler, call)

        return on_call

    def _spawn(self, handler: Callable[[ServiceCall], Awaitable[None]], call: ServiceCall) -> None:
        task: asyncio.Task[None] = asyncio.ensure_future(handler(call))
        self._pending.add(task)
        task.add_done_callback(self._done)

    def _done(self, task: asyncio.Task[None]) -> None:
        self._pending.discard(task)
        if not task.cancelled() and task.exception() is not None:
            logger.warning("%s: a request failed: %r", self.name, task.exception())

    def _decode(self, call: ServiceCall, type_name: str) -> Any:
        """The request, or None (counted, and answered with ``type_name``'s zero response)."""
        try:
            if len(call.payload) > MAX_REQUEST:
                raise ValueError(f"{len(call.payload)} bytes")
            return ros2types.decode(f"{type_name}_Request", call.payload)
        except Exception as exc:
            self.refused["bad_cdr"] += 1
            logger.warning("%s: a %s request that is not one: %s", self.name, type_name, exc)
            call.reply(ros2types.encode(f"{type_name}_Response", self._zero(type_name)))
            return None

    def _zero(self, type_name: str) -> Any:
        return ros2types.default(f"{type_name}_Response")

    async def _goal(self, call: ServiceCall) -> None:
        kind = f"{self.type}_SendGoal"
        request = self._decode(call, kind)
        if request is None:
            return
        goal_id = uuid_bytes(request.goal_id)
        # the handle first: the owner may end the goal, or a cancel come, before the answer
        goal = None if goal_id in self.goals else GoalHandle(goal_id, time.time())
        accepted = False
        if goal is None:
            self.refused["duplicate_goal_id"] += 1
        else:
            self.goals[goal_id] = goal
            try:
                accepted = await self.on_goal(goal_id, request.goal)
            except Exception as exc:  # the owner failed (its database away): not accepted
                self.refused["goal_failed"] += 1
                logger.warning("%s: goal %s not taken: %r", self.name, goal_id.hex(), exc)
            finally:
                if not accepted:
                    self.goals.pop(goal_id, None)
        if goal is not None and accepted:
            goal.decided = True
            if goal.status == ACCEPTED:
                goal.status = EXECUTING
            self.publish_status()
        stamp = goal.stamp if goal is not None else time.time()
        name = f"{kind}_Response"
        response = ros2types.message(name, accepted=accepted, stamp=ros2types.time_msg(stamp))
        call.reply(ros2types.encode(name, response))
        if goal is not None and accepted and goal.status == CANCELING:
            await self.on_cancel(goal_id)  # cancelled while the owner decided: tell it now

    async def _get(self, call: ServiceCall) -> None:
        request = self._decode(call, f"{self.type}_GetResult")
        if request is None:
            return
        goal = self.goals.get(uuid_bytes(request.goal_id))
        if goal is None:
            call.reply(ros2types.encode(*self._result_of(UNKNOWN, None)))
        elif goal.status in ENDED:
            self._answer_result(call, goal)
        else:
            goal.waiting.append(call)

    def _result_of(self, status: int, result: Any) -> tuple[str, Any]:
        name = f"{self.type}_GetResult_Response"
        result = ros2types.default(f"{self.type}_Result") if result is None else result
        return name, ros2types.message(name, status=status, result=result)

    def _answer_result(self, call: ServiceCall, goal: GoalHandle) -> None:
        call.reply(ros2types.encode(*self._result_of(goal.status, goal.result)))

    async def _cancel(self, call: ServiceCall) -> None:
        request = self._decode(call, CANCEL_GOAL)
        if request is None:
            return
        goal_id = uuid_bytes(request.goal_info.goal_id)
        before = ros2types.seconds_of(request.goal_info.stamp)
        # rcl_action's rules: no id and no stamp: every goal; a stamp: those accepted at or
        # before it; an id: that goal (and, with a stamp, those before it too)
        targets = [
            g
            for g in self.goals.values()
            if g.status in (ACCEPTED, EXECUTING)
            and (
                (not any(goal_id) and before == 0.0)
                or g.id == goal_id
                or (before > 0.0 and g.stamp <= before)
            )
        ]
        code = CANCEL_NONE
        if not targets and any(goal_id):
            known = self.goals.get(goal_id)
            code = CANCEL_UNKNOWN_GOAL if known is None else CANCEL_ENDED
            if known is not None and known.status == CANCELING:
                code = CANCEL_NONE  # asked twice: still being cancelled
        for goal in targets:
            goal.status = CANCELING
        if targets:
            self.publish_status()
        name = f"{CANCEL_GOAL}_Response"
        response = ros2types.message(
            name,
            return_code=code,
            goals_canceling=[goal_info(g.id, g.stamp) for g in targets],
        )
        call.reply(ros2types.encode(name, response))
        for goal in targets:
            if goal.decided:  # one still being decided is told of once accepted (_goal)
                await self.on_cancel(goal.id)

    def _forget_old(self) -> None:
        now = time.time()
        ended = sorted(
            (g for g in self.goals.values() if g.ended_at is not None),
            key=lambda g: g.ended_at or 0,
        )
        for i, goal in enumerate(ended):
            if now - (goal.ended_at or now) > RESULT_KEEP_S or i < len(ended) - MAX_ENDED:
                del self.goals[goal.id]


def uuid_bytes(uuid: Any) -> bytes:
    return bytes(np.asarray(uuid.uuid, dtype=np.uint8).tobytes())


def uuid_msg(goal_id: bytes) -> Any:
    return ros2types.message(
        "unique_identifier_msgs/msg/UUID", uuid=np.frombuffer(goal_id, dtype=np.uint8).copy()
    )


def goal_info(goal_id: bytes, stamp: float) -> Any:
    return ros2types.message(
        "action_msgs/msg/GoalInfo", goal_id=uuid_msg(goal_id), stamp=ros2types.time_msg(stamp)
    )

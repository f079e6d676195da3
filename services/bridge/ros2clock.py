"""The stack's clock from ROS time, for a robot with no pybullet sim (``clock: ros``).

The services, and the bridge's own watchdog, run on ``pnav/sim/clock`` (CONTRACT.md). The
pybullet sim publishes it; a real robot does not. With the robot-link file's ``clock: ros``
the bridge publishes it instead, at the sim's rate (``CLOCK_HZ``, 30 Hz of wall time), in ROS
time, the time the robot stamps its messages in:

- ``use_sim_time: false`` (a robot's default): ROS time is the system clock, so the stamp is
  ``time.time()`` with ``rate`` 1 (the services extrapolate between messages, as with the sim);
- ``use_sim_time: true`` (a simulator such as Gazebo drives time): the newest ROS ``/clock``
  (rosgraph_msgs/msg/Clock), with ``rate`` 0: ROS time stands still between ``/clock``
  messages, and so does the stack's. Nothing is published before the first ``/clock``.

A ``/clock`` that is not CDR of the type, not finite or negative is counted (``malformed``,
topic ``ros2/clock``) and dropped; one behind the newest is ignored as the services' clock
ignores a reordered message (one more than a second behind is a restarted simulator, followed).
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Callable
from typing import Final

import zenoh

from common import bus, ros2types
from common.contract import keys
from common.contract import rmw_zenoh as rz
from common.ros2node import Ros2Node, type_of_key

logger = logging.getLogger("pnav.bridge.ros2")

CLOCK_HZ: Final = 30.0  # the pybullet sim's (docs/SIM.md)
CLOCK_TOPIC: Final = "/clock"
CLOCK_TYPE: Final = ros2types.CLOCK
# rclcpp's ClockQoS: best effort, keep last 1
CLOCK_QOS: Final = rz.QoS(reliability=2, depth=1)
TOPIC: Final = "ros2/clock"
RESTART_JUMP_S: Final = 1.0

OnMalformed = Callable[[str, str, str, str], None]  # topic, reason, detail, key


class Ros2Clock:
    """Publishes ``pnav/sim/clock`` on ``session`` (the stack's, as the bridge) from ROS
    time; reads ``/clock`` through ``node`` (the ROS 2 link's) when ``use_sim_time``."""

    def __init__(
        self,
        session: zenoh.Session,
        node: Ros2Node,
        use_sim_time: bool,
        on_malformed: OnMalformed,
    ) -> None:
        self.session = session
        self.use_sim_time = use_sim_time
        self.on_malformed = on_malformed
        self.ros_now: float | None = None  # the newest /clock, seconds
        self.published = 0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._task: asyncio.Task[None] | None = None
        self._publisher = session.declare_publisher(keys.SIM_CLOCK, express=True)
        if use_sim_time:
            node.subscription(CLOCK_TOPIC, CLOCK_TYPE, self._from_zenoh, CLOCK_QOS)
        self._expected = (ros2types.ros_type(CLOCK_TYPE).dds, ros2types.ros_type(CLOCK_TYPE).hash)

    def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._task = asyncio.create_task(self._run(), name="ros2-clock")

    async def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
            try:
                await self._task
            except asyncio.CancelledError:
                pass
        try:
            self._publisher.undeclare()
        except Exception:  # the session is closed already
            pass

    def tick(self) -> tuple[float, float] | None:
        """The (stamp, rate) to publish now; None before the first /clock."""
        if not self.use_sim_time:
            return time.time(), 1.0
        return None if self.ros_now is None else (self.ros_now, 0.0)

    async def _run(self) -> None:
        period = 1.0 / CLOCK_HZ
        while True:
            now = self.tick()
            if now is not None:
                self._publisher.put(bus.pack({"stamp": now[0], "rate": now[1]}))
                self.published += 1
            await asyncio.sleep(period)

    # -- /clock ------------------------------------------------------------------------------
    def _from_zenoh(self, key: str, payload: bytes, att: bytes | None) -> None:
        loop = self._loop
        if loop is None:
            return
        try:
            loop.call_soon_threadsafe(self._on_clock, key, payload)
        except RuntimeError:
            pass  # the loop is closed: shutting down

    def _on_clock(self, key: str, payload: bytes) -> None:
        reason, detail = self._read(key, payload)
        if reason:
            self.on_malformed(TOPIC, reason, detail, key)

    def _read(self, key: str, payload: bytes) -> tuple[str, str]:
        """('', '') when ``payload`` moved ROS time on, else the reason it is refused."""
        if type_of_key(key) != self._expected:
            return "wrong_type", f"{key.rsplit('/', 2)[1]} on {CLOCK_TOPIC}"
        if len(payload) > 1024:
            return "too_large", f"{len(payload)} bytes"
        try:
            stamp = ros2types.seconds_of(ros2types.decode(CLOCK_TYPE, payload).clock)
        except Exception as exc:
            return "bad_cdr", str(exc)[:160]
        if not math.isfinite(stamp) or stamp < 0:
            return "not_finite", f"/clock {stamp}"
        # a little behind is a reordered message; far behind, a restarted simulator: followed
        # (common/clock.py does the same with the services' clock)
        if self.ros_now is None or not 0 < self.ros_now - stamp < RESTART_JUMP_S:
            self.ros_now = stamp
        return "", ""

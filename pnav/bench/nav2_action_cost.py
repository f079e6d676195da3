"""What Nav2's actions cost a client: ``python -m pnav.bench.nav2_action_cost``.

Runs the ``rviz`` process's link (pnav/ros2/rviz.py, serving NavigateToPose for one robot)
on an embedded Postgres with the contract and a Zenoh router on loopback, and times, from a
client session on that router, the service round trips a Nav2 client makes:

- ``send_goal``: a NavigateToPose goal until its ``accepted`` answer: the request over
  Zenoh, the goal row written (the robot's previous goal superseded, in one transaction;
  each goal preempts the one before, as a fleet manager's new order does), the answer back;
- ``cancel_goal``: cancelling that goal until the answer (the goal CANCELING: the answer
  goes before the goal row is cancelled);
- ``get_result``: that goal's result, answered once its row is cancelled (CANCELED).

Every answer is checked (accepted, cancelling one goal, CANCELED): the figures are of goals
that went the whole way.

Each figure is the median, 95th percentile and maximum over ``--goals`` goals, in ms.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import statistics
import struct
import sys
import time
from typing import Any

import asyncpg
import numpy as np
import uvloop
import zenoh

from common import bus, ros2types
from common.config import ServiceConfig, ZenohSettings
from common.contract.migrate import apply_migrations
from common.robotlink import RobotLinkSettings, RobotTopics
from common.ros2action import CANCELED
from common.ros2interfaces import CANCEL_GOAL, NAVIGATE_TO_POSE
from common.runtime import Runtime
from pnav.bench.figures import emit, machine
from pnav.ros2.rviz import RvizLink
from pnav.run.embedded_postgres import EmbeddedPostgres, free_port

STEPS = ("send_goal", "cancel_goal", "get_result")


class Caller:
    """rmw_zenoh's service client, reduced to what is timed: a get with the attachment."""

    def __init__(self, session: zenoh.Session) -> None:
        self.session = session
        self.gid = os.urandom(16)
        self.seq = 0

    def call(self, service: str, type_name: str, request: Any) -> bytes:
        t = ros2types.ros_type(type_name)
        dds = t.dds
        key = f"0/navigate_to_pose/_action/{service}/{dds}/{t.hash}"
        self.seq += 1
        attachment = struct.pack("<qqB", self.seq, time.time_ns(), 16) + self.gid
        payload = ros2types.encode(f"{type_name}_Request", request)
        for reply in self.session.get(
            key,
            payload=payload,
            attachment=attachment,
            target=zenoh.QueryTarget.ALL_COMPLETE,
            timeout=30,
        ):
            if reply.ok is not None:
                return bytes(reply.ok.payload.to_bytes())
        raise RuntimeError(f"no answer from {service}")


def _uuid(goal_id: bytes) -> Any:
    uuid = np.frombuffer(goal_id, dtype=np.uint8).copy()
    return ros2types.message("unique_identifier_msgs/msg/UUID", uuid=uuid)


def _rounds(caller: Caller, goals: int) -> dict[str, list[float]]:
    """Blocking, on a thread of its own: each goal sent, cancelled, its result asked for."""
    times: dict[str, list[float]] = {step: [] for step in STEPS}
    for i in range(goals):
        goal_id = os.urandom(16)
        goal = ros2types.message(
            f"{NAVIGATE_TO_POSE}_Goal",
            pose=ros2types.pose_stamped(0.0, "map", 1.0 + i % 5, 2.0, 0.5),
            behavior_tree="",
        )
        send = ros2types.message(
            f"{NAVIGATE_TO_POSE}_SendGoal_Request", goal_id=_uuid(goal_id), goal=goal
        )
        info = ros2types.message(
            "action_msgs/msg/GoalInfo", goal_id=_uuid(goal_id), stamp=ros2types.time_msg(0.0)
        )
        cancel = ros2types.message(f"{CANCEL_GOAL}_Request", goal_info=info)
        result = ros2types.message(f"{NAVIGATE_TO_POSE}_GetResult_Request", goal_id=_uuid(goal_id))
        for step, kind, request in (
            ("send_goal", f"{NAVIGATE_TO_POSE}_SendGoal", send),
            ("cancel_goal", CANCEL_GOAL, cancel),
            ("get_result", f"{NAVIGATE_TO_POSE}_GetResult", result),
        ):
            start = time.perf_counter()
            answer = caller.call(step, kind, request)
            times[step].append((time.perf_counter() - start) * 1000)
            _check(step, ros2types.decode(f"{kind}_Response", answer))
    return times


def _check(step: str, answer: Any) -> None:
    """The figures are of goals accepted, cancelled and ended, or of nothing."""
    ok = {
        "send_goal": lambda: answer.accepted,
        "cancel_goal": lambda: answer.return_code == 0 and len(answer.goals_canceling) == 1,
        "get_result": lambda: answer.status == CANCELED,
    }[step]()
    if not ok:
        raise RuntimeError(f"{step} answered {answer}")


async def measure(dsn: str, goals: int) -> dict[str, list[float]]:
    conn = await asyncpg.connect(dsn)
    try:
        await apply_migrations(conn)
        await conn.execute("INSERT INTO robot (robot_id) VALUES ('r1')")
    finally:
        await conn.close()
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = bus.start_router((endpoint,))
    settings = ZenohSettings(mode="client", connect=(endpoint,))
    runtime = await Runtime.open(ServiceConfig(service="rviz", database_url=dsn, zenoh=settings))
    ros = await asyncio.to_thread(bus.open_session, settings)
    client = await asyncio.to_thread(bus.open_session, settings)
    link = RvizLink(
        runtime,
        RobotLinkSettings(
            link="ros2", robots={"r1": RobotTopics(namespace="", explicit_namespace=True)}
        ),
        ros,
    )
    await link.start()
    try:
        await asyncio.sleep(1.0)  # the queryables declared on the router
        return await asyncio.to_thread(_rounds, Caller(client), goals)
    finally:
        await link.close()
        client.close()
        ros.close()
        await runtime.close()
        router.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--goals", type=int, default=200)
    parser.add_argument("--json", help="write the figures as JSON to this file ('-': stdout)")
    args = parser.parse_args(argv)
    pg = EmbeddedPostgres()
    pg.start()
    try:
        times = uvloop.run(measure(pg.create_database("nav2bench"), args.goals))
    finally:
        pg.stop()
    result: dict[str, Any] = {"machine": machine(), "goals": args.goals}
    print(f"Nav2 action round trips, {args.goals} goals, ms (median / p95 / max):")
    for step in STEPS:
        values = sorted(times[step])
        p95 = values[min(len(values) - 1, int(0.95 * len(values)))]
        figures = {"median": statistics.median(values), "p95": p95, "max": values[-1]}
        result[step] = figures
        print(f"  {step:12s} {figures['median']:7.2f} {p95:7.2f} {values[-1]:7.2f}")
    emit(result, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())

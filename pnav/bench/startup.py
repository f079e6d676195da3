"""``pnav bench startup``: wall time from launch to the first decided command at the robot,
and the memory of the whole stack, Postgres included.

Each run launches the full stack (embedded Postgres, router, sim, bridge and the four
scenario services) on the warehouse world, writes a goal the moment the robot is registered,
and waits for the first ``cmd_vel`` that carries a ``command_id`` (a decision, not a
watchdog stop). Memory is the proportional set size (PSS) summed over every process of the
stack once the first command has arrived, so pages shared between processes (Postgres'
shared buffers, the Python runtime) are counted once.
"""

from __future__ import annotations

import asyncio
import threading
import time
from typing import Any

import uvloop

from common import bus
from common.config import ServiceConfig
from common.contract import keys
from common.runtime import Runtime
from pnav import commands
from pnav.bench.processes import memory_mb, stack_processes
from pnav.bench.report import emit, machine
from pnav.launcher import StackOptions, launched

TARGET_S, TARGET_MB = 3.0, 500.0


async def one_startup() -> dict[str, Any]:
    first_command = threading.Event()
    marks: dict[str, float] = {}
    t0 = time.monotonic()
    options = StackOptions(world="warehouse", robots=1, zenoh_port=None)
    async with launched(options) as stack:
        marks["infrastructure_s"] = time.monotonic() - t0
        session = bus.open_session(stack.local.zenoh)

        def on_cmd(key: str, payload: bytes) -> None:
            if not first_command.is_set() and bus.unpack(payload).get("command_id") is not None:
                marks["first_command_s"] = time.monotonic() - t0
                first_command.set()

        sub = bus.subscribe_threaded(session, keys.robot_watch(keys.CMD_VEL), on_cmd)
        rt = await Runtime.open(
            ServiceConfig(
                service="bench", database_url=stack.local.database_url, zenoh=stack.local.zenoh
            )
        )
        try:
            (robot,) = await commands.pick_robots(rt, None, one=True)
            marks["robot_registered_s"] = time.monotonic() - t0
            await commands.set_goal(rt, robot, 3.7, 2.5)
            if not await asyncio.to_thread(first_command.wait, 60):
                raise RuntimeError("no decided command reached the sim within 60 s")
            memory = memory_mb(stack_processes(stack))
            processes = len(stack_processes(stack))
        finally:
            await rt.close()
            sub.undeclare()
            session.close()
    return {**{k: round(v, 3) for k, v in marks.items()}, **memory, "processes": processes}


def run(json_path: str | None = None, runs: int = 3) -> int:
    results = [uvloop.run(one_startup()) for _ in range(runs)]
    firsts = sorted(r["first_command_s"] for r in results)
    result = {
        "benchmark": "startup",
        "machine": machine(),
        "runs": results,
        "first_command_s_median": firsts[len(firsts) // 2],
        "pss_mb_max": max(r["pss_mb"] for r in results),
    }
    print("Start-up benchmark (embedded Postgres, router, sim, bridge, 4 scenario services)")
    for i, r in enumerate(results, 1):
        print(
            f"  run {i}: infrastructure {r['infrastructure_s']:.2f} s, robot registered "
            f"{r['robot_registered_s']:.2f} s, first command at sim {r['first_command_s']:.2f} s"
            f"; memory PSS {r['pss_mb']:.0f} MB (RSS sum {r['rss_mb']:.0f} MB, "
            f"{r['processes']} processes)"
        )
    print(
        f"  median first command {result['first_command_s_median']:.2f} s (target < {TARGET_S} s);"
        f" max PSS {result['pss_mb_max']:.0f} MB (target < {TARGET_MB:.0f} MB)"
    )
    emit(result, json_path)
    return 0

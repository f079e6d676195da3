"""``pnav bench startup``: wall time from launch to the first decided command at the robot,
where that time goes, and the memory of the whole stack, Postgres included.

Each run launches the full stack (embedded Postgres, router, sim, bridge and the four
scenario services) on the warehouse world, writes a goal the moment the robot is registered
(its row is looked for every 10 ms), and waits for the first ``cmd_vel`` that carries a
``command_id`` (a decision, not a watchdog stop). Memory is the proportional set size (PSS)
summed over every process of the stack once the first command has arrived, so pages shared
between processes (Postgres' shared buffers, the Python runtime) are counted once; it is
given per process too (``launcher`` is this process: the Zenoh router and the benchmark's
own reading).

Where the time goes: the launcher's steps (pnav.run.local_stack.LocalStack.phases: Postgres' data
directory made, from the template cluster's spare, a copy of it or by initdb, and the server
started; the router;
roles, passwords and migrations), then for each service the first line of its log (it has
imported its code, connected and started: the sim's first line says it runs, once the
bridge listens to it).
"""

from __future__ import annotations

import asyncio
import threading
import time
from datetime import datetime
from pathlib import Path
from typing import Any

import uvloop

from common import bus
from common.config import ServiceConfig
from common.contract import keys
from common.runtime import Runtime
from pnav.bench.figures import emit, machine
from pnav.bench.processes import memory_mb, pss_mb, roles, stack_processes
from pnav.cli import stack_commands
from pnav.run.launcher import launched
from pnav.run.stack_options import StackOptions

TARGET_S, TARGET_MB = 1.0, 300.0  # issue 31
ROBOT_POLL_S = 0.01


async def registered_robot(rt: Runtime, wait_s: float = 60.0) -> str:
    """The robot, the moment the bridge has written its row."""
    deadline = time.monotonic() + wait_s
    while time.monotonic() < deadline:
        rows = await rt.database.pool.fetch("SELECT robot_id FROM robot ORDER BY robot_id")
        if rows:
            robot: str = rows[0]["robot_id"]
            return robot
        await asyncio.sleep(ROBOT_POLL_S)
    raise RuntimeError(f"no robot registered within {wait_s:.0f} s")


def first_lines(log_dir: Path, t0_wall: float) -> dict[str, float]:
    """Per log file (a service's), seconds from launch to its first timestamped line."""
    out = {}
    for path in sorted(log_dir.glob("*.log")):
        for line in path.read_text(errors="replace").splitlines():
            stamp = line.split(" ", 1)[0]
            if not (stamp[:2].isdigit() and stamp.endswith("Z")):
                continue  # pybullet's banner, a traceback's line
            at = datetime.fromisoformat(stamp.replace("Z", "+00:00")).timestamp()
            out[path.stem] = round(at - t0_wall, 3)
            break
    return out


async def one_startup() -> dict[str, Any]:
    first_command = threading.Event()
    marks: dict[str, float] = {}
    t0, t0_wall = time.monotonic(), time.time()
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
            robot = await registered_robot(rt)
            marks["robot_registered_s"] = time.monotonic() - t0
            await stack_commands.set_goal(rt, robot, 3.7, 2.5)
            if not await asyncio.to_thread(first_command.wait, 60):
                raise RuntimeError("no decided command reached the sim within 60 s")
            procs = stack_processes(stack)
            memory = memory_mb(procs)
            per_role = {role: pss_mb(ps) for role, ps in roles(stack).items()}
            postgres_processes = len(roles(stack).get("postgres", []))
        finally:
            await rt.close()
            sub.undeclare()
            session.close()
    return {
        **{k: round(v, 3) for k, v in marks.items()},
        "phases_s": {k: round(v, 3) for k, v in stack.local.phases.items()},
        "postgres_from_template": stack.local.seeded,
        "first_log_line_s": first_lines(stack.log_dir, t0_wall),
        **memory,
        "pss_mb_by_process": per_role,
        "processes": len(procs),
        "postgres_processes": postgres_processes,
    }


def medians_by_source(results: list[dict[str, Any]]) -> dict[str, float]:
    """The median first command of the runs whose cluster came from the spare, from a copy
    of the template, from initdb ("None"): a stack's start is a copy's time slower when no
    earlier stack left a spare (the first start, or ``PNAV_PG_SPARE=0``)."""
    groups: dict[str, list[float]] = {}
    for r in results:
        groups.setdefault(str(r["postgres_from_template"]), []).append(r["first_command_s"])
    return {k: sorted(v)[len(v) // 2] for k, v in sorted(groups.items())}


def run(json_path: str | None = None, runs: int = 3) -> int:
    results = [uvloop.run(one_startup()) for _ in range(runs)]
    firsts = sorted(r["first_command_s"] for r in results)
    result = {
        "benchmark": "startup",
        "machine": machine(),
        "runs": results,
        "first_command_s_median": firsts[len(firsts) // 2],
        "first_command_s_median_by_source": medians_by_source(results),
        "pss_mb_max": max(r["pss_mb"] for r in results),
    }
    print("Start-up benchmark (embedded Postgres, router, sim, bridge, 4 scenario services)")
    for i, r in enumerate(results, 1):
        phases = ", ".join(f"{k} {v:.2f}" for k, v in r["phases_s"].items())
        source = {"spare": "the spare", "copy": "a template copy"}.get(
            r["postgres_from_template"], "initdb"
        )
        lines = ", ".join(f"{k} {v:.2f}" for k, v in r["first_log_line_s"].items())
        pss = ", ".join(f"{k} {v:.0f}" for k, v in r["pss_mb_by_process"].items())
        print(
            f"  run {i}: infrastructure {r['infrastructure_s']:.2f} s ({phases}; Postgres from "
            f"{source}), robot registered {r['robot_registered_s']:.2f} s, first command at "
            f"sim {r['first_command_s']:.2f} s; memory PSS {r['pss_mb']:.0f} MB (RSS sum "
            f"{r['rss_mb']:.0f} MB, {r['processes']} processes, "
            f"{r['postgres_processes']} of them Postgres)\n"
            f"         first log line, s: {lines}\n"
            f"         PSS by process, MB: {pss}"
        )
    by_source = ", ".join(
        f"Postgres from {'initdb' if k == 'None' else k}: {v:.2f} s"
        for k, v in result["first_command_s_median_by_source"].items()
    )
    print(
        f"  median first command {result['first_command_s_median']:.2f} s ({by_source}; target <= "
        f"{TARGET_S:g} s); max PSS {result['pss_mb_max']:.0f} MB (target <= {TARGET_MB:.0f} MB)"
    )
    emit(result, json_path)
    return 0

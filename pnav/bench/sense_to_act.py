"""``pnav bench latency``: sense-to-act latency of the whole stack, by stage, with its cost.

One run per robot count: the full stack (embedded Postgres, router, sim, bridge, the four
scenario services, optionally replicated) on a hall of N lanes (pnav/bench/hall.py), every
robot shuttling along its lane with its lidar and odometry at H Hz, at sim rate 1. After a
warm-up the benchmark measures for S sim seconds:

- latency: from the sim publishing a sensor message to the command decided from it reaching
  the sim, joined through the provenance every command carries (pnav/bench/provenance_samples.py);
- the stages: sensor -> row (bridge), row -> recommendation (planner or controller),
  recommendation -> decision (decision), decision -> robot (bridge, Zenoh);
- CPU seconds and peak memory (PSS) per process, Postgres included (pnav/bench/processes.py);
- rows written per second per table (Postgres' sequences), and the sim rate achieved.

While measuring it reads new command rows every second (sensor rows are pruned after
``keep_rows_per_robot``) and sends each robot to the other end of its lane when it gets
there: two light queries a second, on the same database, counted in ``postgres``.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from common.config import ServiceConfig
from common.runtime import Runtime
from common.trace import CMD_VEL, TraceEvent, read_trace
from pnav.bench import provenance_samples as prov
from pnav.bench.hall import Hall, write_hall
from pnav.bench.processes import Usage
from pnav.cli import stack_commands
from pnav.run.composition import resolve_processes
from pnav.run.launcher import launched
from pnav.run.stack_options import StackOptions

LINKS = ("native", "ros2")
# the stack's own router carries the ROS 2 domain (docs/ROS2.md); nothing else is on it
ROS_DOMAIN = "0"
WARMUP_S = 3.0  # after every robot got its first command: let pools, caches and JITs settle
SEQUENCES = ("odometry", "laser_scan", "battery", "command_recommendation", "command2robot")
# a process's own count of the change notifications that never reached it: the services'
# "engine stopped" line, the bridge's counters line (logged every 10 s and at exit)
LOST = re.compile(r"\b(?:notifications_lost|command_notes_lost)=(\d+)")

COMMANDS_SQL = """
SELECT c.id, c.robot_id, c.recommendation_id,
       extract(epoch FROM c.created_at)::float8 AS decided,
       r.source, extract(epoch FROM r.created_at)::float8 AS recommended, r.inputs
  FROM command2robot c JOIN command_recommendation r ON r.id = c.recommendation_id
 WHERE c.id > $1 ORDER BY c.id
"""
COMMANDED_SQL = (
    "SELECT count(DISTINCT robot_id) FROM command2robot WHERE recommendation_id IS NOT NULL"
)
RULES_SQL = """
SELECT service, rule_type, executed, total_time_s, max_time_s FROM engine_stats
 WHERE executed > 0 ORDER BY service, total_time_s DESC
"""
SENSOR_SQL = """
SELECT id, robot_id, seq, extract(epoch FROM received_at)::float8 AS received
  FROM {table} WHERE id = ANY($1::bigint[])
"""


@dataclass
class Collected:
    commands: list[prov.Command] = field(default_factory=list)
    rows: dict[tuple[str, int], prov.SensorRow] = field(default_factory=dict)
    last_id: int = 0


async def collect(rt: Runtime, into: Collected) -> None:
    """Command rows newer than the last read, and the sensor rows they name."""
    async with rt.database.pool.acquire() as conn:
        records = await conn.fetch(COMMANDS_SQL, into.last_id)
        wanted: dict[str, list[int]] = {}
        for r in records:
            cmd = prov.Command(
                r["id"],
                r["robot_id"],
                r["recommendation_id"],
                r["decided"],
                r["source"],
                r["recommended"],
                r["inputs"],
            )
            into.commands.append(cmd)
            into.last_id = max(into.last_id, cmd.command_id)
            origin = prov.origin_of(cmd.inputs)
            if origin is not None and (origin[0], origin[2]) not in into.rows:
                wanted.setdefault(origin[0], []).append(origin[2])
        for table, ids in wanted.items():
            for s in await conn.fetch(SENSOR_SQL.format(table=table), ids):
                into.rows[(table, s["id"])] = prov.SensorRow(
                    table, s["id"], s["robot_id"], s["seq"], s["received"]
                )


async def sequences(rt: Runtime) -> dict[str, int]:
    rows = await rt.database.pool.fetch(
        "SELECT sequencename, coalesce(last_value, 0) AS n FROM pg_sequences "
        "WHERE schemaname = current_schema() AND sequencename = ANY($1::text[])",
        [f"{t}_id_seq" for t in SEQUENCES],
    )
    return {r["sequencename"].removesuffix("_id_seq"): int(r["n"]) for r in rows}


class Shuttle:
    """Sends each robot to the other end of its lane once it got where it was going."""

    def __init__(self, rt: Runtime, hall: Hall) -> None:
        self.rt = rt
        self.lanes = {lane.robot_id: lane for lane in hall.lanes}
        self.leg = dict.fromkeys(self.lanes, 0)
        self.legs_done = 0

    async def send(self, robot: str) -> None:
        lane = self.lanes[robot]
        x, y = lane.b if self.leg[robot] % 2 == 0 else lane.a
        await stack_commands.set_goal(self.rt, robot, x, y)

    async def start(self) -> None:
        for robot in self.lanes:
            await self.send(robot)

    async def turn_around(self) -> None:
        rows = await self.rt.database.pool.fetch(
            "SELECT DISTINCT ON (robot_id) robot_id, status FROM goal ORDER BY robot_id, id DESC"
        )
        for r in rows:
            if r["status"] != "active" and r["robot_id"] in self.lanes:
                self.leg[r["robot_id"]] += 1
                self.legs_done += 1
                await self.send(r["robot_id"])


async def wait_for_count(
    rt: Runtime, sql: str, count: int, what: str, limit_s: float = 60.0
) -> None:
    """Poll ``sql`` (a count) until it reaches ``count``; RuntimeError naming ``what``."""
    deadline = time.monotonic() + limit_s
    while (n := await rt.database.pool.fetchval(sql)) < count:
        if time.monotonic() > deadline:
            raise RuntimeError(f"only {n} of {count} robots {what} within {limit_s:.0f} s")
        await asyncio.sleep(0.2)


async def rule_times(rt: Runtime) -> list[dict[str, Any]]:
    """Each rule type's mean and longest run, its awaited queries included, from the
    services' engine_stats (the whole run, start-up and warm-up included)."""
    records = await rt.database.pool.fetch(RULES_SQL)
    return [
        {
            "service": r["service"],
            "rule": r["rule_type"],
            "executed": r["executed"],
            "mean_ms": round(r["total_time_s"] / r["executed"] * 1000, 3),
            "max_ms": round(r["max_time_s"] * 1000, 2),
        }
        for r in records
    ]


def link_env(link: str, bridge_trace: Path) -> dict[str, str]:
    """The stack's variables for ``link``: the ROS 2 link as `pnav up --robot-link ros2` sets
    it (the sim plays a ROS 2 robot on the stack's router), with the bridge's trace."""
    if link == "native":
        return {}
    return {
        "PNAV_ROBOT_LINK": link,
        "PNAV_ROS_DOMAIN_ID": ROS_DOMAIN,
        "PNAV_BRIDGE_TRACE": str(bridge_trace),
    }


def join_trace(
    sim: list[TraceEvent], bridge: list[TraceEvent] | None
) -> tuple[dict[tuple[str, str, int], float], dict[int, float]]:
    """When each sensor message was published, by (kind, robot, the row's ``seq``), and when
    each command id reached the robot. On the ROS 2 link (``bridge`` given) a row's ``seq`` is
    the attachment's number and the sim knows a cmd_vel only by its attachment's number: the
    bridge's trace says which command id went out as which (common/trace.py)."""
    published: dict[tuple[str, str, int], float] = {}
    arrivals: dict[int, float] = {}
    sent = None if bridge is None else {(e.robot, e.wire): e.ref for e in bridge}
    for e in sim:
        at = e.wall_ns / 1e9
        if e.kind != CMD_VEL:
            published[(e.kind, e.robot, e.ref if sent is None else e.wire)] = at
            continue
        command_id = e.ref if sent is None else sent.get((e.robot, e.wire))
        if command_id is not None:
            arrivals.setdefault(command_id, at)
    return published, arrivals


async def measure(
    robots: int,
    hz: float,
    seconds: float,
    replicas: dict[str, int],
    link: str = "native",
    processes: str | None = None,
) -> dict[str, Any]:
    """One run: the stack with ``robots`` robots on ``link``, measured for ``seconds`` sim
    seconds; ``processes``: the stack's layout (None: PNAV_PROCESSES, else ``auto``)."""
    work = Path(tempfile.mkdtemp(prefix=f"pnav-latency-{robots}-{link}-"))
    hall = write_hall(work / "world", robots)
    trace_path, bridge_trace = work / "trace.csv", work / "bridge-trace.csv"
    options = StackOptions(
        world=str(hall.world),
        zenoh_port=None,
        log_dir=work / "logs",
        replicas=replicas,
        extra_env={
            "PNAV_SIM_SCAN_HZ": str(hz),
            "PNAV_SIM_ODOM_HZ": str(hz),
            "PNAV_SIM_TRACE": str(trace_path),
            **link_env(link, bridge_trace),
        },
    )
    if processes is not None:
        options = replace(options, processes=processes)
    async with launched(options) as stack:
        config = ServiceConfig(
            service="bench", database_url=stack.local.database_url, zenoh=stack.local.zenoh
        )
        rt = await Runtime.open(config)
        try:
            await wait_for_count(rt, "SELECT count(*) FROM robot", robots, "registered")
            shuttle = Shuttle(rt, hall)
            await shuttle.start()
            await wait_for_count(rt, COMMANDED_SQL, robots, "got a command")
            await asyncio.sleep(WARMUP_S)
            collected = Collected()
            await collect(rt, collected)  # the warm-up's commands are read, not counted
            seq0, sim0, t0 = await sequences(rt), rt.clock.now(), time.time()
            usage = Usage(stack)
            async with usage.measuring():
                wall_limit = time.monotonic() + 3 * seconds + 30
                while rt.clock.now() - sim0 < seconds and time.monotonic() < wall_limit:
                    await asyncio.sleep(0.5)
                    await shuttle.turn_around()
                    await collect(rt, collected)
            t1, sim1, seq1 = time.time(), rt.clock.now(), await sequences(rt)
            await asyncio.sleep(1.0)  # the last commands land and the trace is flushed
            await collect(rt, collected)
            rules = await rule_times(rt)
        finally:
            with contextlib.suppress(Exception):
                await rt.close()
    lost = notifications_lost(work / "logs")
    published, arrivals = join_trace(
        read_trace(trace_path), None if link == "native" else read_trace(bridge_trace)
    )
    all_samples, unmatched = prov.samples(arrivals, collected.commands, collected.rows, published)
    samples = [s for s in all_samples if t0 <= s.published <= t1]
    wall = t1 - t0
    return {
        "link": link,
        "layout": resolve_processes(options.processes),
        "robots": robots,
        "hz": hz,
        "replicas": replicas,
        "sim_s": round(sim1 - sim0, 2),
        "wall_s": round(wall, 2),
        "sim_rate": round((sim1 - sim0) / wall, 3) if wall > 0 else 0.0,
        "legs_done": shuttle.legs_done,
        "samples": len(samples),
        "unmatched": vars(unmatched),
        "samples_raw": samples,
        "rows_per_s": {t: round((seq1.get(t, 0) - seq0.get(t, 0)) / wall, 1) for t in SEQUENCES},
        "processes": usage.report(),
        "rules": rules,
        "notifications_lost": lost,
        "work_dir": str(work),
    }


def notifications_lost(log_dir: Path) -> dict[str, int]:
    """Per process (its log's name), the change notifications it never got, over the whole
    run: its last count in its log (processes that keep none are left out)."""
    out: dict[str, int] = {}
    for path in sorted(log_dir.glob("*.log")):
        counts = LOST.findall(path.read_text(errors="replace"))
        if counts:
            out[path.stem] = int(counts[-1])
    return out

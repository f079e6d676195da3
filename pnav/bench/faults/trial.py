"""One mission with one fault: launch the stack, send r1 off, inject mid-way, follow it to
its end, measure.

The stack is launched as ``pnav up`` launches it (embedded Postgres, supervised services),
except that every service is pointed at a Zenoh router in a process of its own, which the
freeze faults can stop alone. The fault goes in once r1 has driven ``INJECT_AFTER_M``; the
committed rows are snapshotted just before, and looked for again once the stack has
recovered (commands flowing again after the fault ended).
"""

from __future__ import annotations

import asyncio
import math
import re
import shutil
import tempfile
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from common.config import ServiceConfig
from common.contract import keys
from common.contract.grants import USER
from common.outage import is_connection_error
from common.runtime import Runtime
from common.trace import CMD_VEL, read_trace
from pnav._testing import router_process
from pnav.bench.faults import committed_rows
from pnav.bench.faults.catalogue import Fault
from pnav.bench.faults.context import FORGED_COMMAND_ID, ROBOT, SPOOF_SEQ, Context
from pnav.bench.faults.inject import inject
from pnav.cli import stack_commands
from pnav.run.launcher import launched
from pnav.run.local_stack import BusCredentials
from pnav.run.mission import GoalEnded, MissionMonitor
from pnav.run.stack_options import DashboardOptions, StackOptions

T = TypeVar("T")

INJECT_AFTER_M = 1.0
START_LIMIT_S = 120.0  # stack up to r1 under way
MISSION_LIMIT_S = 150.0  # fault injected to the mission's end
RECOVERY_LIMIT_S = 60.0
REACHED_SLACK_M = 0.1  # a goal counts as truly reached within its tolerance and this
# the tables the bridge writes with synchronous_commit off (services/bridge/writer.py)
ASYNC_COMMIT = frozenset({keys.ODOMETRY, keys.LASER_SCAN, keys.BATTERY})


@dataclass
class Result:
    fault: str
    what: str
    outcome: str = "not run"  # reached | failed: reason | refused (exit 2) ... | timeout | error
    safe: bool = False  # completed, or ended safely with a reason
    collisions: int = 0  # collision_event rows during the mission
    contacts: int | None = None  # the sim's own count (its last run's "sim stopped" line)
    max_after_command_m: float | None = None
    rows_lost: dict[str, int] = field(default_factory=dict)
    rows_checked: int = 0
    restart_s: float | None = None
    recovered_s: float | None = None  # fault over -> a new command2robot row after new odom
    # forged messages that had an effect: spoofed odometry rows stored, forged cmd_vel the
    # sim applied (None: the fault forges nothing)
    forged_believed: int | None = None
    wall_s: float = 0.0
    notes: list[str] = field(default_factory=list)
    breaches: list[str] = field(default_factory=list)  # what an attack achieved


async def _newest(rt: Runtime, table: str) -> int:
    value = await rt.database.pool.fetchval(f"SELECT coalesce(max(id), 0) FROM {table}")
    return int(value)


async def _reachable(rt: Runtime, query: Callable[[], Awaitable[T]]) -> T:
    """``query()``, retried while the bench's own pool is still backing off from the fault
    (a Postgres the launcher just restarted: common.outage), for RECOVERY_LIMIT_S."""
    deadline = time.monotonic() + RECOVERY_LIMIT_S
    while True:
        try:
            return await query()
        except Exception as exc:
            if not is_connection_error(exc) or time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.2)


async def _recovered(rt: Runtime, since: float) -> float | None:
    """Wall seconds from ``since`` until odometry and then a decision are written anew."""
    odom = await _reachable(rt, lambda: _newest(rt, keys.ODOMETRY))
    cmd = await _reachable(rt, lambda: _newest(rt, keys.COMMAND2ROBOT))
    while time.monotonic() < since + RECOVERY_LIMIT_S:
        new_odom = await _reachable(rt, lambda: _newest(rt, keys.ODOMETRY))
        new_cmd = await _reachable(rt, lambda: _newest(rt, keys.COMMAND2ROBOT))
        if new_odom > odom and new_cmd > cmd:
            return round(time.monotonic() - since, 2)
        await asyncio.sleep(0.1)
    return None


async def _rows_lost(rt: Runtime, snapshot: committed_rows.Snapshot) -> dict[str, int]:
    async with rt.database.pool.acquire() as conn:
        return await committed_rows.lost(conn, snapshot)


def sim_figures(sim_log: Path) -> dict[str, float]:
    """``contacts`` and ``max_after_command_m`` of every "sim stopped" line (a killed sim
    writes none): summed and maxed over the sim's runs."""
    try:
        text = sim_log.read_text(errors="replace")
    except OSError:
        return {}
    out: dict[str, float] = {}
    for line in text.splitlines():
        if "sim stopped" not in line:
            continue
        found = dict(re.findall(r"(contacts|max_after_command_m)=([0-9.]+)", line))
        if "contacts" in found:
            out["contacts"] = out.get("contacts", 0) + int(found["contacts"])
        if "max_after_command_m" in found:
            m = float(found["max_after_command_m"])
            out["max_after_command_m"] = max(out.get("max_after_command_m", 0.0), m)
    return out


def forged_commands_applied(trace: Path) -> int | None:
    """The forged cmd_vel the sim applied, by its own trace (common/trace.py); None
    without a trace (the sim never ran)."""
    if not trace.is_file():
        return None
    events = read_trace(trace)
    return sum(1 for e in events if e.kind == CMD_VEL and e.ref >= FORGED_COMMAND_ID)


async def _true_distance(rt: Runtime, goal: tuple[float, float]) -> float:
    """r1's distance to ``goal`` by the sim's own odometry (spoofed rows left out)."""
    row = await rt.database.pool.fetchrow(
        f"SELECT x, y FROM {keys.ODOMETRY} WHERE robot_id = $1 AND seq < $2 "
        "ORDER BY id DESC LIMIT 1",
        ROBOT,
        SPOOF_SEQ,
    )
    return math.inf if row is None else math.hypot(row["x"] - goal[0], row["y"] - goal[1])


async def run_trial(
    fault: Fault,
    world: Path,
    goal: tuple[float, float],
    bad_goals: dict[str, tuple[float, float]],
    rate: str,
    log_dir: Path,
) -> Result:
    result = Result(fault.name, fault.what)
    started = time.monotonic()
    # the stack's Zenoh users, checked by the router process too, with the same access
    # control: a forger meets the same defence as on a `pnav up` stack (pnav.run.local_stack)
    secrets_dir = Path(tempfile.mkdtemp(prefix="pnav-bus-"))
    bus = BusCredentials.create(secrets_dir)
    try:
        with router_process(bus.users_file) as (router, plain):
            zenoh = bus.apply(plain, USER)
            trace = (
                {"PNAV_SIM_TRACE": str(log_dir / "trace.csv")} if fault.kind == "cmd_vel" else {}
            )
            options = StackOptions(
                world=str(world),
                rate=rate,
                robots=1,
                zenoh_port=None,
                log_dir=log_dir,
                # the router process; each service keeps its user
                extra_env={**plain.to_env(), **trace},
                bus=bus,
                # the dashboard's attacks need one; the other faults run without
                dashboard=DashboardOptions(port=None) if fault.kind == "dashboard" else None,
            )
            async with launched(options) as stack:
                config = ServiceConfig(
                    service="faults", database_url=stack.local.database_url, zenoh=zenoh
                )
                rt = await Runtime.open(config)
                try:
                    ctx = Context(stack, router, zenoh, rt, goal, 0, bad_goals, bus)
                    await _mission(fault, ctx, result)
                finally:
                    await rt.close()
    finally:
        shutil.rmtree(secrets_dir, ignore_errors=True)
    if fault.kind == "cmd_vel":  # the sim's trace is complete once it stopped
        result.forged_believed = forged_commands_applied(log_dir / "trace.csv")
        applied = "no trace" if result.forged_believed is None else result.forged_believed
        result.notes.append(f"{applied} forged cmd_vel applied by the sim")
    figures = sim_figures(log_dir / "sim.log")
    result.contacts = int(figures["contacts"]) if "contacts" in figures else None
    result.max_after_command_m = figures.get("max_after_command_m")
    result.wall_s = round(time.monotonic() - started, 1)
    return result


async def _mission(fault: Fault, ctx: Context, result: Result) -> None:
    rt = ctx.rt
    monitor = MissionMonitor(rt.database.pool, ROBOT)
    if not await monitor.wait_for(lambda log: log.now.stamp > 0, START_LIMIT_S):
        result.outcome = "error: no odometry from the stack"
        return
    ctx.goal_id = await stack_commands.set_goal(rt, ROBOT, *ctx.goal)
    under_way = await monitor.wait_for(
        lambda log: log.distance_m >= INJECT_AFTER_M, START_LIMIT_S, goal=ctx.goal_id
    )
    if not under_way:
        result.outcome = "error: r1 never got under way"
        return
    collisions_before = monitor.log.collisions
    async with rt.database.pool.acquire() as conn:
        snapshot = await committed_rows.snapshot(conn)
    injection = await inject(fault, ctx)
    ended = time.monotonic()
    result.restart_s = injection.restart_s
    result.forged_believed = injection.forged_believed
    result.notes += [n for n in injection.notes if n]
    result.breaches = injection.breaches
    result.recovered_s = await _recovered(rt, ended)
    result.rows_lost = await _reachable(rt, lambda: _rows_lost(rt, snapshot))
    result.rows_checked = snapshot.rows
    if result.rows_lost and set(result.rows_lost) <= ASYNC_COMMIT:
        result.notes.append(
            "sensor rows the bridge commits with synchronous_commit off and restores after "
            "a crash (docs/BRIDGE.md): lost all the same"
        )
    follow = injection.follow_goal or ctx.goal_id
    result.outcome, result.safe = await _follow(monitor, rt, fault, ctx, follow, injection)
    await monitor.poll()
    result.collisions = monitor.log.collisions - collisions_before


async def _follow(
    monitor: MissionMonitor, rt: Runtime, fault: Fault, ctx: Context, goal_id: int, inj: Any
) -> tuple[str, bool]:
    prefix = ""
    if fault.kind == "dashboard":
        if inj.breaches:
            return f"NOT refused: {'; '.join(inj.breaches)}", False
        prefix = f"refused: {inj.refused}; then "
    if fault.kind == "cli":
        if inj.exit_code != 2:
            return f"NOT refused (exit {inj.exit_code}): {inj.refused}", False
        prefix = f"refused (exit 2): {inj.refused}; then "
    try:
        ok = await monitor.wait_for(
            lambda log: log.goals.get(goal_id) == "reached", MISSION_LIMIT_S, goal=goal_id
        )
    except GoalEnded as end:
        return f"{prefix}failed: {end.reason}", True
    if not ok:
        return f"{prefix}timeout ({MISSION_LIMIT_S:.0f} s)", False
    off = await _true_distance(rt, ctx.goal)
    if off > 0.15 + REACHED_SLACK_M:
        return f"{prefix}FOOLED: goal marked reached {off:.2f} m from it", False
    return f"{prefix}reached", True

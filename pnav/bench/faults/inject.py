"""Injecting one fault into a running stack, and how long the stack took to get over it.

What each kind means here:

- ``kill``: SIGKILL of the service's process; ``restart_s`` is the time until its new
  process declared its liveliness token (``pnav/alive/{service}/*``) again.
- ``postgres``: SIGKILL of the embedded postmaster (``postmaster.pid``); ``restart_s`` is
  the time until a connection succeeds again (the launcher's Keeper restarted it).
- ``freeze``: SIGSTOP, then SIGCONT, of the Zenoh router. The bench runs the router in a
  process of its own (``common.testing.router_process``, as the router-freeze test does) and
  points every service at it, so the router alone is frozen.
- ``cut``: SIGSTOP, then SIGCONT, of one service's process: its links to the router and to
  Postgres are cut (sockets open, nothing moves) as a pulled cable would, and come back.
- ``spoof``: a rogue Zenoh client, a process not given this run's Zenoh password, tries to
  publish odometry for r1 at its goal (seq from 10^9, so its rows, if any got in, can be
  told apart afterwards).
- ``rogue``: a rogue writer inserts a full-speed recommendation at priority 1000 (the safety
  band: refused by the database unless it is a stop), then at 99, every 0.1 s.
- ``cli``: ``pnav goal`` with a value the door must refuse (exit 2, one line).
- ``goal``: ``pnav goal`` to a point outside the map or inside a rack: accepted, then failed
  by the planner with its reason.
- ``stall``: a strategy row asking dwa for its heaviest decisions (GOTO_FAST with
  :data:`DWA_STALL`: each size within its documented range), r1 switched to it for the rest of
  the mission; after ``seconds`` the controller's engine_stats say its longest rule run and
  how often safety_stop ran and recommended meanwhile.
"""

from __future__ import annotations

import asyncio
import dataclasses
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from typing import Any

import asyncpg
import zenoh

from common import bus
from common.config import ZenohSettings
from common.contract import keys
from common.errors import ConnectionFailure
from common.postmaster import postmaster_pid
from common.runtime import Runtime
from pnav import commands
from pnav.bench.faults.catalogue import Fault
from pnav.launcher import RunningStack

ROBOT = "r1"
SPOOF_SEQ = 10**9
# the hostile tester's strategy params (issue 28): 255,000 poses a decision as asked
DWA_STALL = {"dwa_steps": 50, "dwa_linear_samples": 50, "dwa_angular_samples": 100,
             "dwa_horizon_s": 10}  # fmt: skip
STALL_CODE = "DWA_STALL"
_WAIT_S = 60.0  # the longest wait for a restart


@dataclass
class Context:
    stack: RunningStack
    router: subprocess.Popen[str]
    zenoh: ZenohSettings
    rt: Runtime
    goal: tuple[float, float]
    goal_id: int
    bad_goals: dict[str, tuple[float, float]]


@dataclass
class Injection:
    restart_s: float | None = None
    refused: str | None = None  # the door's one line, for a refused value
    exit_code: int | None = None
    follow_goal: int | None = None  # the goal the mission now follows, if it changed
    notes: list[str] = field(default_factory=list)


class Liveliness:
    """When tokens under ``pnav/alive/{service}/*`` appear (wall time, monotonic)."""

    def __init__(self, session: zenoh.Session, service: str) -> None:
        self.appeared: list[float] = []
        self.changed = asyncio.Event()
        self._loop = asyncio.get_running_loop()
        self._sub = session.liveliness().declare_subscriber(keys.alive_key(service, "*"), self._on)

    def _on(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            self.appeared.append(time.monotonic())
            self._loop.call_soon_threadsafe(self.changed.set)

    async def after(self, t0: float, limit_s: float) -> float | None:
        """The first appearance after ``t0``, waiting up to ``limit_s``; None if none."""
        deadline = t0 + limit_s
        while not (back := [t for t in self.appeared if t > t0]):
            self.changed.clear()
            try:
                await asyncio.wait_for(self.changed.wait(), max(0.0, deadline - time.monotonic()))
            except TimeoutError:
                return None
        return back[0]

    def close(self) -> None:
        self._sub.undeclare()


async def inject(fault: Fault, ctx: Context) -> Injection:
    handler = {
        "kill": _kill,
        "postgres": _kill_postgres,
        "freeze": _freeze,
        "cut": _cut,
        "spoof": _spoof,
        "rogue": _rogue,
        "cli": _bad_value,
        "goal": _bad_goal,
        "stall": _stall,
    }[fault.kind]
    return await handler(fault, ctx)


async def _kill(fault: Fault, ctx: Context) -> Injection:
    child = ctx.stack.supervisor.children[fault.target]
    watch = Liveliness(ctx.rt.zenoh, fault.target)
    try:
        assert child.process is not None
        t0 = time.monotonic()
        child.process.kill()
        back = await watch.after(t0, _WAIT_S)
        if back is None:
            return Injection(notes=[f"{fault.target} not back within {_WAIT_S:.0f} s"])
        return Injection(restart_s=round(back - t0, 2))
    finally:
        watch.close()


async def _kill_postgres(fault: Fault, ctx: Context) -> Injection:
    postgres = ctx.stack.local.postgres
    if postgres is None:
        return Injection(notes=["PNAV_DATABASE_URL names a server: not ours to kill"])
    pid = postmaster_pid(postgres.data_dir)
    if pid is None:
        return Injection(notes=["no postmaster.pid"])
    t0 = time.monotonic()
    os.kill(pid, signal.SIGKILL)
    await asyncio.sleep(0.2)
    while time.monotonic() < t0 + _WAIT_S:
        try:
            conn = await asyncpg.connect(ctx.stack.local.database_url, timeout=2)
        except (OSError, asyncpg.PostgresError, TimeoutError):
            await asyncio.sleep(0.1)
            continue
        await conn.close()
        return Injection(restart_s=round(time.monotonic() - t0, 2))
    return Injection(notes=["Postgres not back within 60 s"])


async def _stop_for(pid: int, seconds: float) -> None:
    os.kill(pid, signal.SIGSTOP)
    try:
        await asyncio.sleep(seconds)
    finally:
        os.kill(pid, signal.SIGCONT)


async def _freeze(fault: Fault, ctx: Context) -> Injection:
    await _stop_for(ctx.router.pid, fault.seconds)
    return Injection()


async def _cut(fault: Fault, ctx: Context) -> Injection:
    child = ctx.stack.supervisor.children[fault.target]
    assert child.process is not None
    await _stop_for(child.process.pid, fault.seconds)
    return Injection()


async def _spoof(fault: Fault, ctx: Context) -> Injection:
    # a process on the machine that was not given a password (common.stack.BusCredentials)
    outsider = dataclasses.replace(ctx.zenoh, user=None, password=None, users_file=None)
    try:
        rogue = await asyncio.to_thread(bus.open_session, outsider)
    except ConnectionFailure as exc:
        return Injection(notes=[f"the router refused the spoofer's session: {exc}"])
    try:
        key = keys.robot_key(ROBOT, keys.ODOM)
        x, y = ctx.goal
        end = time.monotonic() + fault.seconds
        seq = SPOOF_SEQ
        while time.monotonic() < end:
            body = {"stamp": ctx.rt.clock.now(), "seq": seq, "x": x, "y": y, "yaw": 0.0}
            rogue.put(key, bus.pack({**body, "linear": 0.0, "angular": 0.0}))
            seq += 1
            await asyncio.sleep(1 / 30)
        return Injection(notes=[f"{seq - SPOOF_SEQ} spoofed odometry messages"])
    finally:
        rogue.close()


_RECOMMEND = f"""
INSERT INTO {keys.COMMAND_RECOMMENDATION} (robot_id, kind, source, priority, linear_mps,
    angular_rps, stamp, expires_stamp, inputs, reason)
VALUES ($1, 'robot', 'rogue', $2, 0.22, 0.0, $3::float8, $3::float8 + 0.5, '{{}}',
        'fault injection')
RETURNING id"""


async def _recommend(rt: Runtime, priority: int) -> Any:
    return await rt.database.write(
        keys.COMMAND_RECOMMENDATION, ROBOT, _RECOMMEND, ROBOT, priority, rt.clock.now()
    )


async def _rogue(fault: Fault, ctx: Context) -> Injection:
    out = Injection()
    try:
        await _recommend(ctx.rt, 1000)
        out.notes.append("priority 1000 accepted by the database")
    except asyncpg.CheckViolationError as exc:
        out.notes.append(f"priority 1000 refused by the database ({exc.constraint_name})")
    end, sent = time.monotonic() + fault.seconds, 0
    while time.monotonic() < end:
        await _recommend(ctx.rt, 99)
        sent += 1
        await asyncio.sleep(0.1)
    out.notes.append(f"{sent} priority-99 recommendations of 0.22 m/s straight ahead")
    return out


def _cli_env(ctx: Context) -> dict[str, str]:
    return {**os.environ, "PNAV_DATABASE_URL": ctx.stack.local.database_url, **ctx.zenoh.to_env()}


async def _pnav_goal(ctx: Context, *argv: str) -> tuple[int, str]:
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "pnav",
        "goal",
        *argv,
        "--robot",
        ROBOT,
        env=_cli_env(ctx),
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )
    out, err = await asyncio.wait_for(proc.communicate(), 60)
    text = (err or out).decode(errors="replace").strip()
    return proc.returncode or 0, text


async def _bad_value(fault: Fault, ctx: Context) -> Injection:
    before = await ctx.rt.database.pool.fetchval(f"SELECT count(*) FROM {keys.GOAL}")
    code, text = await _pnav_goal(ctx, *fault.argv)
    after = await ctx.rt.database.pool.fetchval(f"SELECT count(*) FROM {keys.GOAL}")
    out = Injection(exit_code=code, refused=text.splitlines()[-1] if text else "")
    if after != before:
        out.notes.append(f"{after - before} goal row(s) written")
    return out


async def _bad_goal(fault: Fault, ctx: Context) -> Injection:
    x, y = ctx.bad_goals[fault.goal]
    code, text = await _pnav_goal(ctx, repr(x), repr(y))
    out = Injection(exit_code=code, notes=[text.splitlines()[-1] if text else ""])
    if code == 0:
        out.follow_goal = await ctx.rt.database.pool.fetchval(
            f"SELECT max(id) FROM {keys.GOAL} WHERE robot_id = $1", ROBOT
        )
    return out


_STALL_STRATEGY = f"""
INSERT INTO {keys.STRATEGY} (code, planner_scenario, controller_scenarios, params, description)
SELECT $1, planner_scenario, controller_scenarios, params || $2::jsonb,
       'GOTO_FAST asking dwa for its heaviest decisions (pnav bench faults, dwa-stall)'
FROM {keys.STRATEGY} WHERE code = 'GOTO_FAST'
ON CONFLICT (code) DO NOTHING"""

_CONTROLLER_RULES = f"""
SELECT rule_type, sum(executed) AS executed, sum(acted) AS acted, max(max_time_s) AS max_s
FROM {keys.ENGINE_STATS} WHERE service = 'controller' GROUP BY rule_type"""


async def _controller_rules(rt: Runtime) -> dict[str, Any]:
    return {r["rule_type"]: r for r in await rt.database.pool.fetch(_CONTROLLER_RULES)}


async def _stall(fault: Fault, ctx: Context) -> Injection:
    rt = ctx.rt
    await rt.database.write(keys.STRATEGY, None, _STALL_STRATEGY, STALL_CODE, DWA_STALL)
    before = await _controller_rules(rt)
    verdict, reason = await commands.send_user_command(rt, ROBOT, "SET_STRATEGY", STALL_CODE)
    out = Injection(notes=[f"SET_STRATEGY {STALL_CODE}: {verdict} {reason}".strip()])
    # the mission drives on under it; engine_stats are written every 2 s (PNAV_STATS_PERIOD_S)
    await asyncio.sleep(fault.seconds)
    after = await _controller_rules(rt)
    if after:
        longest = max(after.values(), key=lambda r: r["max_s"])
        out.notes.append(
            f"controller's longest rule run: {longest['rule_type']} "
            f"{longest['max_s'] * 1e3:.1f} ms (rule budget 50 ms)"
        )
    stop, was = after.get("SafetyStop"), before.get("SafetyStop")
    ran = (stop["executed"] - (was["executed"] if was else 0)) if stop else 0
    acted = (stop["acted"] - (was["acted"] if was else 0)) if stop else 0
    out.notes.append(
        f"safety_stop ran {ran} times ({acted} recommendations) in the {fault.seconds:.0f} s"
        if ran
        else "safety_stop did NOT run during the stall"
    )
    return out

"""Injecting one fault into a running stack, and how long the stack took to get over it.

What each kind means here:

- ``kill``: SIGKILL of the service's process; ``restart_s`` is the time until its new
  process declared its liveliness token (``pnav/alive/{service}/*``) again.
- ``postgres``: SIGKILL of the embedded postmaster (``postmaster.pid``); ``restart_s`` is
  the time until a connection succeeds again (the launcher's Keeper restarted it).
- ``freeze``: SIGSTOP, then SIGCONT, of the Zenoh router. The bench runs the router in a
  process of its own (``pnav._testing.router_process``, as the router-freeze test does) and
  points every service at it, so the router alone is frozen.
- ``cut``: SIGSTOP, then SIGCONT, of one service's process: its links to the router and to
  Postgres are cut (sockets open, nothing moves) as a pulled cable would, and come back.
- ``spoof``: a rogue Zenoh client tries to publish odometry for r1 at its goal (seq from
  10^9, so its rows, if any got in, can be told apart afterwards): first as a process not
  given this run's Zenoh password (the router refuses its session), then with people's
  identity, the CLI's (``pnav env user``): the router's access control drops every message
  (only the sim puts sensor messages). The forged rows stored are counted 2 s after the last
  one was sent (before retention could prune them): none.
- ``cmd_vel``: people's identity puts ``cmd_vel`` for r1 straight to the sim (a hard
  turn at full speed, ``command_id`` from 10^9): only the bridge may, so the router drops
  them. The trial reads the sim's own trace (PNAV_SIM_TRACE) for a forged command it
  applied: none.
- ``rogue``: a rogue writer with the controller's database role and Zenoh identity (a
  compromised controller: people's identity may not announce a recommendation) inserts a
  full-speed recommendation at priority 1000 (the safety band: refused by the database
  unless it is a stop), then at 99, every 0.1 s.
- ``forge``: forged command_recommendation and command2robot row images on r1's keys, put
  with the identities the Zenoh ACL lets put them (forge.py); a command citing a forgery, or
  a cmd_vel relaying one, is a breach.
- ``cli``: ``pnav goal`` with a value the door must refuse (exit 2, one line).
- ``goal``: ``pnav goal`` to a point outside the map or inside a rack: accepted, then failed
  by the planner with its reason.
- ``theft``: as ``pnav_user``, every lock and lease call against r1's leases, round after
  round (pnav.bench.faults.theft); a call not refused, or r1's owner in any service changing,
  is a breach.
- ``dashboard``: an attack on the stack's dashboard, which must refuse it and go on serving
  (anything it let through is a breach): ``deep-params`` posts a strategy
  whose params nest 500 deep and inserts one as a database client would (refused by the
  dashboard, 4xx, and by the strategy table's CHECK); ``dns-rebinding`` posts a goal and
  opens the websocket as a page of evil.example pointed at 127.0.0.1 would (403 both).
- ``stall``: a strategy row asking dwa for its heaviest decisions (stall.py: GOTO_FAST with
  :data:`DWA_STALL`: each size within its documented range), r1 switched to it for the rest of
  the mission; after ``seconds`` the controller's engine_stats say its longest rule run and
  how often safety_stop ran and recommended meanwhile.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import os
import signal
import sys
import time
from collections.abc import AsyncIterator
from typing import Any

import asyncpg
import zenoh

from common import bus
from common.contract import keys
from common.contract.grants import USER
from common.db import Database, create_pool
from common.errors import ConnectionFailure
from common.postmaster import postmaster_pid
from common.runtime import Runtime
from pnav.bench.faults import tablelock, theft
from pnav.bench.faults.catalogue import Fault
from pnav.bench.faults.context import FORGED_COMMAND_ID, ROBOT, SPOOF_SEQ, Context, Injection
from pnav.bench.faults.dashboard import attack_dashboard
from pnav.bench.faults.forge import forge
from pnav.bench.faults.stall import stall

_WAIT_S = 60.0  # the longest wait for a restart
# the bridge stores a sensor message within milliseconds; retention keeps 30 sim seconds
_STORED_WITHIN_S = 2.0


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
        "cmd_vel": _forged_cmd_vel,
        "rogue": _rogue,
        "forge": _forge,
        "cli": _bad_value,
        "goal": _bad_goal,
        "theft": _lease_theft,
        "dashboard": attack_dashboard,
        "stall": stall,
        "tablelock": tablelock.inject,
    }[fault.kind]
    return await handler(fault, ctx)


async def _kill(fault: Fault, ctx: Context) -> Injection:
    # a composed service's process is the host: killing it kills its co-hosted services too
    child = ctx.stack.supervisor.children[ctx.stack.process_of(fault.target)]
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
    child = ctx.stack.supervisor.children[ctx.stack.process_of(fault.target)]
    assert child.process is not None
    await _stop_for(child.process.pid, fault.seconds)
    return Injection()


async def _as(ctx: Context, identity: str) -> zenoh.Session:
    """A Zenoh session of the stack's ``identity``, with its password (USER: what
    ``pnav env user`` gives the CLI and the dashboard)."""
    return await asyncio.to_thread(bus.open_session, ctx.bus.apply(ctx.zenoh, identity))


async def _at_30_hz(seconds: float, put: Any) -> int:
    """Call ``put(i)`` 30 times a second for ``seconds``; how many times."""
    end, sent = time.monotonic() + seconds, 0
    while time.monotonic() < end:
        put(sent)
        sent += 1
        await asyncio.sleep(1 / 30)
    return sent


async def _spoof(fault: Fault, ctx: Context) -> Injection:
    out = Injection()
    # a process on the machine that was not given a password (pnav.run.local_stack.BusCredentials)
    outsider = dataclasses.replace(ctx.zenoh, user=None, password=None, users_file=None)
    try:
        (await asyncio.to_thread(bus.open_session, outsider)).close()
        out.notes.append("the router gave a session to a client without a password")
    except ConnectionFailure:
        out.notes.append("the router refused the session of a client without a password")
    # people's identity: a password every CLI of the run has, and no right to sensors
    rogue = await _as(ctx, USER)
    try:
        key = keys.robot_key(ROBOT, keys.ODOM)
        x, y = ctx.goal

        def put(i: int) -> None:
            body = {"stamp": ctx.rt.clock.now(), "seq": SPOOF_SEQ + i, "x": x, "y": y}
            rogue.put(key, bus.pack({**body, "yaw": 0.0, "linear": 0.0, "angular": 0.0}))

        sent = await _at_30_hz(fault.seconds, put)
        out.notes.append(f"{sent} odometry messages forged as {USER}")
    finally:
        rogue.close()
    await asyncio.sleep(_STORED_WITHIN_S)
    stored = await ctx.rt.database.pool.fetchval(
        f"SELECT count(*) FROM {keys.ODOMETRY} WHERE robot_id = $1 AND seq >= $2",
        ROBOT,
        SPOOF_SEQ,
    )
    out.forged_believed = int(stored)
    out.notes.append(f"{stored} forged odometry rows stored")
    return out


async def _forged_cmd_vel(fault: Fault, ctx: Context) -> Injection:
    rogue = await _as(ctx, USER)
    try:
        key = keys.robot_key(ROBOT, keys.CMD_VEL)

        def put(i: int) -> None:
            # full speed and a hard turn: off the path, into the racks, if it were obeyed
            body = {"stamp": ctx.rt.clock.now(), "linear": 0.22, "angular": 2.5}
            rogue.put(key, bus.pack({**body, "command_id": FORGED_COMMAND_ID + i}))

        sent = await _at_30_hz(fault.seconds, put)
        return Injection(notes=[f"{sent} cmd_vel forged as {USER}, straight to the sim"])
    finally:
        rogue.close()


@contextlib.asynccontextmanager
async def _writer_as(ctx: Context, identity: str) -> AsyncIterator[Database]:
    """A writer with ``identity``'s database role and Zenoh identity (no liveliness token:
    not a replica, nothing a lease or ``pnav status`` counts)."""
    session = await _as(ctx, identity)
    try:
        pool = await create_pool(ctx.stack.local.url_for(identity), max_size=1)
        db = Database(pool, bus.Notifier(session))
        try:
            yield db
        finally:
            await db.close()
    finally:
        session.close()


_RECOMMEND = f"""
INSERT INTO {keys.COMMAND_RECOMMENDATION} (robot_id, kind, source, priority, linear_mps,
    angular_rps, stamp, expires_stamp, inputs, reason)
VALUES ($1, 'robot', 'rogue', $2, 0.22, 0.0, $3::float8, $3::float8 + 0.5, '{{}}',
        'fault injection')
RETURNING id"""


async def _recommend(db: Database, rt: Runtime, priority: int) -> Any:
    return await db.write(
        keys.COMMAND_RECOMMENDATION, ROBOT, _RECOMMEND, ROBOT, priority, rt.clock.now()
    )


async def _rogue(fault: Fault, ctx: Context) -> Injection:
    out = Injection()
    async with _writer_as(ctx, "controller") as db:
        try:
            await _recommend(db, ctx.rt, 1000)
            out.notes.append("priority 1000 accepted by the database")
        except asyncpg.CheckViolationError as exc:
            out.notes.append(f"priority 1000 refused by the database ({exc.constraint_name})")
        end, sent = time.monotonic() + fault.seconds, 0
        while time.monotonic() < end:
            await _recommend(db, ctx.rt, 99)
            sent += 1
            await asyncio.sleep(0.1)
    out.notes.append(f"{sent} priority-99 recommendations of 0.22 m/s straight ahead")
    return out


async def _forge(fault: Fault, ctx: Context) -> Injection:
    return await forge(fault, ctx, ROBOT)


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


async def _lease_theft(fault: Fault, ctx: Context) -> Injection:
    url = ctx.stack.local.url_for(USER)
    async with ctx.rt.database.pool.acquire() as watch:
        stolen = await theft.steal(url, watch, ROBOT, fault.seconds)
    return Injection(notes=[stolen.summary()], breaches=stolen.breaches())

"""``pnav goal | strategy | cancel | status | down``: drive a running stack from any terminal.

Each command writes contract rows as a person's tool would (with their notifications) and
reads the answers back from the tables; none talks to a service directly.
"""

from __future__ import annotations

import asyncio
import math
import os
import shlex
import signal
import sys
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

import asyncpg

from common.config import ServiceConfig
from common.contract import people
from common.errors import ContractError, UsageError
from common.runtime import Runtime
from pnav.run import stackfile


async def open_runtime() -> Runtime:
    url, zenoh = stackfile.connection()
    config = ServiceConfig(service="cli", database_url=url, zenoh=zenoh, db_wait_s=3.0)
    return await Runtime.open(config)


async def robot_ids(rt: Runtime, wait_s: float = 10.0) -> list[str]:
    """Robots known to the contract, waiting a little for the bridge to register them."""
    deadline = time.monotonic() + wait_s
    while True:
        rows = await rt.database.pool.fetch("SELECT robot_id FROM robot ORDER BY robot_id")
        if rows or time.monotonic() > deadline:
            return [r["robot_id"] for r in rows]
        await asyncio.sleep(0.2)


async def pick_robots(rt: Runtime, robot: str | None, *, one: bool) -> list[str]:
    known = await robot_ids(rt)
    if robot is not None:
        if robot not in known:
            raise UsageError(f"no robot {robot!r}; known robots: {', '.join(known) or 'none'}")
        return [robot]
    if not known:
        raise UsageError("no robot is registered yet: is the sim running?")
    if one and len(known) > 1:
        raise UsageError(f"several robots ({', '.join(known)}): name one with --robot")
    return known


@contextmanager
def refusal_as_contract_error() -> Iterator[None]:
    """Turn the database refusing a row (a CHECK, a foreign key, a value it cannot store)
    into a one-line ContractError: the row came from the user, so it is a usage error, and
    the constraint's name finds its reason in CONTRACT.md ("Refused values")."""
    try:
        yield
    except (asyncpg.IntegrityConstraintViolationError, asyncpg.DataError) as exc:
        # asyncpg's client-side DataError may run over several lines; the first says it
        detail = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise ContractError(f"the database refused the row: {detail}") from None


async def check_strategy(rt: Runtime, code: str) -> None:
    """UsageError unless ``code`` is a row of the strategy table."""
    known = [
        r["code"] for r in await rt.database.pool.fetch("SELECT code FROM strategy ORDER BY code")
    ]
    if code not in known:
        raise UsageError(f"unknown strategy {code!r}; known strategies: {', '.join(known)}")


async def set_goal(
    rt: Runtime,
    robot: str,
    x: float,
    y: float,
    tolerance: float | None = None,
    *,
    yaw: float | None = None,
    yaw_tolerance_rad: float | None = None,
    waypoints: Sequence[people.Pose] = (),
) -> int:
    """:func:`set_route` to the pose (x, y), ``yaw`` in radians."""
    goal = people.Pose(x, y, yaw, yaw_tolerance_rad, tolerance)
    return await set_route(rt, robot, goal, waypoints)


async def set_route(
    rt: Runtime, robot: str, goal: people.Pose, waypoints: Sequence[people.Pose] = ()
) -> int:
    """Supersede the robot's active goal and set a new one (a pose, and a route's waypoints
    before it), in one transaction.

    A value the goal or goal_waypoint table would refuse raises ContractError, naming it,
    before anything is written."""
    people.check_route(goal, waypoints)
    return await people.set_route(rt.database, robot, goal, waypoints)


async def cancel_goal(rt: Runtime, robot: str) -> int | None:
    return await people.cancel_goal(rt.database, robot)


async def send_user_command(
    rt: Runtime, robot: str, command: str, argument: str | None, wait_s: float = 5.0
) -> tuple[str, str]:
    """Insert a user_command and wait for the strategy service's verdict (status, reason)."""
    command_id = await people.user_command(rt.database, robot, command, argument)
    deadline = time.monotonic() + wait_s
    while time.monotonic() < deadline:
        row = await rt.database.pool.fetchrow(
            "SELECT status, reason FROM user_command WHERE id = $1", command_id
        )
        if row["status"] != "pending":
            return row["status"], row["reason"] or ""
        await asyncio.sleep(0.05)
    return "pending", f"no answer from the strategy service within {wait_s:.0f} s"


STATUS_SQL = """
SELECT r.robot_id,
       o.stamp, o.x, o.y, o.yaw, o.linear_mps, o.angular_rps,
       g.id AS goal_id, g.x AS gx, g.y AS gy, g.status AS goal_status, g.reason AS goal_reason,
       a.strategy_code, a.resume_code,
       b.percentage, b.charging,
       c.linear_mps AS cmd_v, c.angular_rps AS cmd_w, c.source AS cmd_source, c.reason,
       (SELECT count(*) FROM collision_event e WHERE e.robot_id = r.robot_id) AS collisions
FROM robot r
LEFT JOIN LATERAL (SELECT * FROM odometry WHERE robot_id = r.robot_id
                   ORDER BY id DESC LIMIT 1) o ON true
LEFT JOIN LATERAL (SELECT * FROM goal WHERE robot_id = r.robot_id
                   ORDER BY status = 'active' DESC, id DESC LIMIT 1) g
       ON g.status IN ('active', 'failed')
LEFT JOIN active_strategy a ON a.robot_id = r.robot_id
LEFT JOIN LATERAL (SELECT * FROM battery WHERE robot_id = r.robot_id
                   ORDER BY id DESC LIMIT 1) b ON true
LEFT JOIN LATERAL (SELECT * FROM command2robot WHERE robot_id = r.robot_id
                   ORDER BY id DESC LIMIT 1) c ON true
ORDER BY r.robot_id
"""


def _fmt(value: Any, spec: str, missing: str = "-") -> str:
    return missing if value is None else format(value, spec)


async def owners(rt: Runtime) -> tuple[dict[str, int], dict[str, list[str]]]:
    """Live replicas per scenario service, and robot -> the owning instance of each service
    that runs more than one replica (a lone replica owns every robot: nothing to show)."""
    from common import lease
    from pnav.run.stack_options import SCENARIO_SERVICES

    replicas: dict[str, int] = {}
    owned: dict[str, list[str]] = {}
    async with rt.database.pool.acquire() as conn:
        for service in SCENARIO_SERVICES:
            replicas[service] = await lease.live_replicas(conn, service)
            if replicas[service] > 1:
                for robot, instance in (await lease.ownership(conn, service)).items():
                    owned.setdefault(robot, []).append(instance or f"{service}: nobody")
    return replicas, owned


def status_lines(
    rows: Sequence[Any], width: int = 160, owned: dict[str, list[str]] | None = None
) -> list[str]:
    header = (
        f"{'robot':<6} {'sim t':>7} {'x':>6} {'y':>6} {'yaw':>5} {'goal':>13} {'left':>5} "
        f"{'strategy':<12} {'batt':>6} {'cmd v':>6} {'cmd w':>6} {'coll':>4}  "
        + ("owners  " if owned else "")
        + "last decision"
    )
    lines = [header]
    for r in rows:
        # the active goal; else the newest goal if it failed (until another is set)
        failed = r["goal_id"] is not None and r.get("goal_status") == "failed"
        goal = "-" if r["goal_id"] is None else f"({r['gx']:.1f},{r['gy']:.1f})"
        goal = "failed" if failed else goal
        left = None
        if r["goal_id"] is not None and r["x"] is not None and not failed:
            left = math.hypot(r["gx"] - r["x"], r["gy"] - r["y"])
        strategy = r["strategy_code"] or "-"
        if r["resume_code"]:
            strategy += "*"
        batt = "-" if r["percentage"] is None else f"{r['percentage']:.1f}%"
        if r["charging"]:
            batt += "+"
        decision = (
            "-"
            if r["cmd_source"] is None and r["reason"] is None
            else (f"{r['cmd_source'] or 'stop'}: {r['reason'] or ''}")
        )
        line = (
            f"{r['robot_id']:<6} {_fmt(r['stamp'], '7.1f')} {_fmt(r['x'], '6.2f')} "
            f"{_fmt(r['y'], '6.2f')} {_fmt(r['yaw'], '5.2f')} {goal:>13} {_fmt(left, '5.2f')} "
            f"{strategy:<12} {batt:>6} {_fmt(r['cmd_v'], '6.2f')} {_fmt(r['cmd_w'], '6.2f')} "
            f"{r['collisions']:>4}  "
            + (f"{','.join(owned.get(r['robot_id'], ['-']))}  " if owned else "")
            + decision
        )
        lines.append(line[:width])
        if failed:
            why = f"       goal {r['goal_id']} failed: {r.get('goal_reason') or 'no reason given'}"
            lines.append(why[:width])
    return lines


async def status(once: bool, interval_s: float = 1.0) -> int:
    rt = await open_runtime()
    try:
        while True:
            rows = await rt.database.pool.fetch(STATUS_SQL)
            replicas, owned = await owners(rt)
            width = os.get_terminal_size().columns if sys.stdout.isatty() else 200
            lines = status_lines(rows, width, owned)
            if any(n > 1 for n in replicas.values()):
                lines.append(
                    "replicas: " + ", ".join(f"{name} {n}" for name, n in replicas.items())
                )
            text = "\n".join(lines)
            if once:
                print(text)
                return 0
            print("\x1b[2J\x1b[H" + text, flush=True)  # clear screen, home
            await asyncio.sleep(interval_s)
    finally:
        await rt.close()


def env(role: str) -> int:
    """Print ``export`` lines that make a process started by hand join the running stack as
    ``role``: its Postgres role's DSN and its Zenoh user (both with this run's passwords)."""
    info = stackfile.read()
    if info is None:
        raise UsageError("no running stack: start one with `pnav up`")
    for name, value in info.env_for(role).items():
        print(f"export {name}={shlex.quote(value)}")
    return 0


def down(wait_s: float = 20.0) -> int:
    info = stackfile.read()
    if info is None:
        print("no running stack")
        return 0
    os.kill(info.pid, signal.SIGTERM)
    deadline = time.monotonic() + wait_s
    while time.monotonic() < deadline:
        if stackfile.read() is None:
            print(f"stack {info.pid} stopped")
            return 0
        time.sleep(0.1)
    print(f"stack {info.pid} did not stop within {wait_s:.0f} s", file=sys.stderr)
    return 1


async def migrate(wait_s: float, *, roles: bool = False) -> int:
    """Apply the contract's migrations to PNAV_DATABASE_URL (the compose one-shot job); with
    ``roles``, as pnav_owner after creating every role and before granting (common.contract.
    roles), the role passwords read from PNAV_DB_PASSWORD_*."""
    from common.contract.migrate import apply_migrations, current_version
    from common.contract.roles import bootstrap
    from common.db import create_pool
    from pnav.run.credentials import db_passwords_from_env

    url = os.environ.get("PNAV_DATABASE_URL", "").strip()
    if not url:
        raise UsageError("PNAV_DATABASE_URL is not set: which database should be migrated?")
    passwords = db_passwords_from_env() if roles else {}
    pool = await create_pool(url, max_size=1, wait_s=wait_s)
    try:
        async with pool.acquire() as conn:
            if roles:
                applied = await bootstrap(conn, passwords)
            else:
                applied = await apply_migrations(conn)
            version = await current_version(conn)
    finally:
        await pool.close()
    print(f"contract at version {version}; applied now: {applied or 'nothing'}")
    return 0

"""What a statement costs the service that sends it: ``python -m pnav.bench.statement_cost``.

The client's CPU (``time.process_time`` of this process: the service's side, not the
backend's) per statement on the embedded Postgres, in a uvloop process like a service's,
three ways:

- ``pool``: ``async with pool.acquire() as conn: await conn.fetchrow(...)``, what every
  statement of a service did before common/lane.py;
- ``lane``: ``Lane.fetchrow``, the held connection a service's ``Database`` now uses;
- ``connection``: a bare asyncpg connection, the floor.

Two statements: the controller's newest-odometry read (an index lookup returning one row)
and a one-row INSERT ... RETURNING id with its commit, as a recommendation's. Best of
``--rounds`` rounds of ``--n`` statements each; ``--json FILE`` writes the figures.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Awaitable, Callable
from typing import Any

import asyncpg
import uvloop

from common.db import create_pool
from common.lane import Lane
from pnav.run.embedded_postgres import EmbeddedPostgres

SETUP = (
    "CREATE TABLE lane_probe (id bigserial PRIMARY KEY, robot_id text NOT NULL, stamp float8,"
    " x float8, y float8, yaw float8, linear_mps float8, angular_rps float8)",
    "CREATE INDEX ON lane_probe (robot_id, id DESC)",
    "INSERT INTO lane_probe (robot_id, stamp, x, y, yaw, linear_mps, angular_rps)"
    " SELECT 'r' || (i % 10), i, 1, 2, 3, 0.1, 0.2 FROM generate_series(1, 5000) AS i",
)
READ = (
    "SELECT id, robot_id, stamp, x, y, yaw, linear_mps, angular_rps FROM lane_probe"
    " WHERE robot_id = $1 ORDER BY id DESC LIMIT 1"
)
WRITE = (
    "INSERT INTO lane_probe (robot_id, stamp, x, y, yaw, linear_mps, angular_rps)"
    " VALUES ($1, 1, 2, 3, 4, 5, 6) RETURNING id"
)

Statement = Callable[[], Awaitable[Any]]


async def cpu_per_call(call: Statement, n: int, rounds: int) -> float:
    """The best round's client CPU per call, in microseconds."""
    for _ in range(min(n, 300)):
        await call()  # warm: prepared statements, caches
    best = float("inf")
    for _ in range(rounds):
        started = time.process_time()
        for _ in range(n):
            await call()
        best = min(best, (time.process_time() - started) / n)
    return best * 1e6


async def measure(n: int, rounds: int) -> dict[str, dict[str, float]]:
    pg = EmbeddedPostgres()
    pg.start()
    try:
        dsn = pg.dsn()
        conn = await asyncpg.connect(dsn)
        for sql in SETUP:
            await conn.execute(sql)
        pool = await create_pool(dsn, min_size=2, max_size=4)
        lane = Lane(pool)

        def pooled(method: str, sql: str) -> Statement:
            async def call() -> Any:
                async with pool.acquire() as c:
                    return await getattr(c, method)(sql, "r3")

            return call

        ways: dict[str, dict[str, Statement]] = {
            "pool": {"read": pooled("fetchrow", READ), "write": pooled("fetchval", WRITE)},
            "lane": {
                "read": lambda: lane.fetchrow(READ, "r3"),
                "write": lambda: lane.fetchval(WRITE, "r3"),
            },
            "connection": {
                "read": lambda: conn.fetchrow(READ, "r3"),
                "write": lambda: conn.fetchval(WRITE, "r3"),
            },
        }
        figures: dict[str, dict[str, float]] = {}
        for way, statements in ways.items():
            figures[way] = {
                name: round(await cpu_per_call(call, n, rounds), 1)
                for name, call in statements.items()
            }
        await lane.close()
        await pool.close()
        await conn.close()
        return figures
    finally:
        pg.stop()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m pnav.bench.statement_cost", description=__doc__)
    ap.add_argument("--n", type=int, default=3000, help="statements per round (default 3000)")
    ap.add_argument("--rounds", type=int, default=3, help="rounds, best kept (default 3)")
    ap.add_argument("--json", help="write the figures as JSON to FILE")
    args = ap.parse_args(argv)
    figures = uvloop.run(measure(args.n, args.rounds))
    print("client CPU per statement, us (best of rounds; embedded Postgres)")
    print(f"{'':12s} {'read':>8s} {'write':>8s}")
    for way, row in figures.items():
        print(f"{way:12s} {row['read']:8.1f} {row['write']:8.1f}")
    if args.json:
        with open(args.json, "w") as out:
            json.dump(figures, out, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())

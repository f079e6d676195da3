"""The states a kept run's decisions were made in, as scenes for ``python -m pnav.bench.learned
--db-dir``: each decision's scan, odometry, path in force and robot row, read from a database
``pnav bench nav --keep-db`` kept (through ``pnav learn dataset``'s reading, so the states are
the ones its examples are made of)."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

from common.contract.planned_path import PlannedPath, planned_path_of
from common.contract.records import LaserScan, Odometry, Robot, laser_scan_of, odometry_of, robots
from common.errors import UsageError
from pnav.learn import dataset

State = tuple[LaserScan, Odometry, PlannedPath, Robot]


class _Collect:
    """A labeller that labels nothing and keeps each decision's state."""

    name = "recorded"
    cell: tuple[int, list[bool]] | None = None  # no lattice labels

    def __init__(self, by_robot: dict[str, Robot]) -> None:
        self.robots = by_robot
        self.states: list[State] = []
        self._paths: dict[int, PlannedPath] = {}  # one object per row, as a controller has

    def __call__(
        self, robot_id: str, scan: Any, odom: Any, path: Any
    ) -> tuple[float, float] | None:
        if path["id"] not in self._paths:
            self._paths[path["id"]] = planned_path_of(path)
        state = (
            laser_scan_of(scan),
            odometry_of(odom),
            self._paths[path["id"]],
            self.robots[robot_id],
        )
        self.states.append(state)
        return None


async def _read(db_dir: Path) -> list[State]:
    import asyncpg

    from pnav.run.embedded_postgres import EmbeddedPostgres

    postgres = EmbeddedPostgres(db_dir)
    postgres.start()
    try:
        conn = await asyncpg.connect(postgres.dsn())
        try:
            collect = _Collect({r.robot_id: r for r in await robots(conn)})
            await dataset.read(conn, label=collect)
        finally:
            await conn.close()
    finally:
        postgres.stop()
    return collect.states


def states(db_dirs: list[Path]) -> list[State]:
    """Every decision's state in these kept databases, in order."""
    out: list[State] = []
    for d in db_dirs:
        if not (d / "PG_VERSION").is_file():
            raise UsageError(f"--db-dir {d}: not a Postgres data directory")
        out.extend(asyncio.run(_read(d)))
    return out

"""Relabelling recorded states with dwa's decision for them (``pnav learn dataset --label
dwa``): the step of DAgger that the stack's records make possible.

A policy distilled from dwa's decisions (learned_drive) drifts into states dwa never put the
robot in, where its training set says nothing. Every state it reached is in its run's
database: the scan, the odometry and the path in force of each decision, the robot row (its
limits and footprint) and the strategy row. dwa's choice is a pure function of those
(:func:`pnav_local.dwa.choose`), so it can be asked offline what it would have commanded in
each of them; the answers are the labels, and training on them together with dwa's own runs
teaches the policy what to do where it actually goes.

dwa's params are the ``dwa_*`` keys of a strategy row of the same database: the robot's
active strategy (GOTO_LEARNED names none, so dwa's defaults, as under GOTO_FAST), or the
strategy ``--label-strategy`` names.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

from common.contract.planned_path import PlannedPath, planned_path_of
from common.contract.records import (
    LaserScan,
    Odometry,
    Robot,
    laser_scan_of,
    odometry_of,
    robots,
)
from common.errors import UsageError
from pnav_learned import lattice
from pnav_learned.candidates import Scene
from pnav_learned.features import to_robot_frame
from pnav_local import dwa
from pnav_local.dwa_params import DwaParams

LABELS = ("dwa",)


class DwaLabeller:
    """dwa's command for a recorded state, with the robot row and the strategy's params (a
    ``dataset.Labeller``); None where dwa is silent (no point of the path ahead)."""

    name = "dwa"
    # the last state's (dwa's cell on the lattice, the admissible cells): None when dwa had
    # nothing to say (pnav learn dataset's dwa_cell and dwa_admissible columns)
    cell: tuple[int, list[bool]] | None = None

    def __init__(self, robot: Mapping[str, Robot], params: Mapping[str, DwaParams]) -> None:
        self.robot = robot
        self.params = params
        # one PlannedPath object per row: dwa keeps the last path's arrays by identity
        self._path: tuple[int, PlannedPath] | None = None

    def __call__(
        self,
        robot_id: str,
        scan: Mapping[str, Any],
        odom: Mapping[str, Any],
        path: Mapping[str, Any],
    ) -> tuple[float, float] | None:
        if self._path is None or self._path[0] != path["id"]:
            self._path = (path["id"], planned_path_of(path))
        robot = self.robot[robot_id]
        choice = dwa.choose(
            laser_scan_of(scan),
            odometry_of(odom),
            robot,
            self._path[1],
            self.params[robot_id],
            robot.footprint_polygon,
        )
        if choice is None:
            self.cell = None
            return None
        command = dwa.command_for(choice, self._path[1])
        self.cell = cell_of(
            (command.linear, command.angular), laser_scan_of(scan), odometry_of(odom), robot,
            self.params[robot_id], self._path[1],
        )  # fmt: skip
        return command.linear, command.angular


def cell_of(
    command: tuple[float, float],
    scan: LaserScan,
    odom: Odometry,
    robot: Robot,
    p: DwaParams,
    path: PlannedPath,
) -> tuple[int, list[bool]]:
    """(the cell of dwa's lattice nearest ``command``, which cells are admissible): the
    lattice and the check learned_drive uses at run time (pnav_learned.lattice, .candidates),
    for the state's window."""
    tx, ty = to_robot_frame(path.xs[-1], path.ys[-1], (odom.x, odom.y, odom.yaw))
    scene = Scene(scan, odom, robot, p, math.hypot(tx, ty), robot.footprint_polygon)
    ok, _ = scene.admissible(*lattice.grid(scene.bounds))
    return lattice.nearest(command, scene.bounds), ok.tolist()


async def labeller(conn: Any, label: str, strategy: str | None = None) -> DwaLabeller:
    """The labeller ``label`` names, for the database ``conn`` opens: its robot rows, and
    dwa's params from ``strategy``'s row (None: each robot's active strategy's)."""
    if label not in LABELS:
        raise UsageError(f"--label {label!r}: one of {', '.join(LABELS)}")
    by_robot = {r.robot_id: r for r in await robots(conn)}
    params: dict[str, DwaParams] = {}
    if strategy is not None:
        row = await conn.fetchrow("SELECT params FROM strategy WHERE code = $1", strategy)
        if row is None:
            raise UsageError(f"--label-strategy {strategy!r}: no such strategy in the database")
        params = dict.fromkeys(by_robot, DwaParams.read(_json(row["params"])))
    else:
        rows = await conn.fetch(
            "SELECT a.robot_id, s.params FROM active_strategy a"
            " JOIN strategy s ON s.code = a.strategy_code"
        )
        found = {r["robot_id"]: DwaParams.read(_json(r["params"])) for r in rows}
        params = {robot: found.get(robot, DwaParams()) for robot in by_robot}
    return DwaLabeller(by_robot, params)


def _json(value: Any) -> dict[str, Any]:
    loaded = json.loads(value) if isinstance(value, str) else value
    return dict(loaded or {})

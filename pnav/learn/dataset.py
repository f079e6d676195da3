"""``pnav learn dataset``: the stack's records as training examples, one per decision.

A decision is a ``command2robot`` row. What the scenarios saw is read through provenance:
the winning ``command_recommendation`` (``recommendation_id``) names in ``inputs`` the
``laser_scan``, ``odometry`` and ``planned_path`` rows it was made from; a winner that names
fewer (the planner's move scenarios read odometry only; a stop with no live recommendation
names none) takes the robot's newest row of that table at or before the decision's stamp.
A decision with no scan, odometry or non-empty path to describe it is skipped (counted).

What happened, ``horizon_s`` of sim time on: ``progress_m`` (distance to the path's target
now minus then, from the first odometry at or after stamp + horizon; NaN when the run ended
sooner), ``collision`` (a collision_event in [stamp, stamp + horizon]) and ``goal_status``
(the status of the goal the path led to, as the database has it now).

Each example also carries foresight's features of the last seconds (pnav_learned.history,
``HISTORY_FEATURES``), from the robot's earlier examples in stamp order: the scenario
computes them the same way from its scans.
"""

from __future__ import annotations

import bisect
import json
import math
from collections import defaultdict
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from pnav_learned.features import FEATURES, features, sector_minima
from pnav_learned.history import HISTORY_FEATURES, History, sample

DEFAULT_HORIZON_S = 3.0

Row = Mapping[str, Any]


class Labeller(Protocol):
    """What :func:`read` labels each decision's state with: (robot_id, scan row, odometry
    row, planned_path row) -> (linear, angular), or None where it has nothing to say (dwa:
    no point of the path ahead, it is silent); ``name`` is each example's ``source``.
    relabel.DwaLabeller labels with dwa's choice; pnav.bench.recorded keeps the states."""

    name: str
    # the last state's (dwa's cell on the lattice, the admissible cells), where the
    # labeller has them (the dwa_cell and dwa_admissible columns); None where it has not
    cell: tuple[int, list[bool]] | None

    def __call__(
        self, robot_id: str, scan: Row, odom: Row, path: Row
    ) -> tuple[float, float] | None: ...


# the example's columns beside the features (Parquet column names)
META = ("decision_id", "robot_id", "stamp", "strategy", "scan_id", "odometry_id", "path_id")
TARGETS = ("linear_mps_cmd", "angular_rps_cmd")
OUTCOMES = ("source", "progress_m", "collision", "goal_status")
# with a label (relabel.py): what the stack decided, beside the label's targets
DECIDED = ("decided_linear_mps", "decided_angular_rps", "decided_source")
# with dwa's label: its choice's cell of dwa's lattice (pnav_learned.lattice; -1: none) and
# which cells are admissible (learned_drive's check, per cell: the lattice classifier's data)
LATTICE = ("dwa_cell", "dwa_admissible")


@dataclass
class Rows:
    """One robot's rows of a table, by id and in stamp order."""

    by_id: dict[int, Any] = field(default_factory=dict)
    stamps: list[float] = field(default_factory=list)
    rows: list[Any] = field(default_factory=list)

    def add(self, row: Any) -> None:
        self.by_id[row["id"]] = row
        self.stamps.append(row["stamp"])
        self.rows.append(row)

    def at_or_before(self, stamp: float) -> Any | None:
        i = bisect.bisect_right(self.stamps, stamp)
        return self.rows[i - 1] if i else None

    def at_or_after(self, stamp: float) -> Any | None:
        i = bisect.bisect_left(self.stamps, stamp)
        return self.rows[i] if i < len(self.rows) else None

    def named(self, inputs: dict[str, Any], key: str, stamp: float) -> Any | None:
        """The row the recommendation names, else the newest one at ``stamp``."""
        ident = inputs.get(key)
        if isinstance(ident, int) and ident in self.by_id:
            return self.by_id[ident]
        return self.at_or_before(stamp)


async def _by_robot(conn: Any, sql: str) -> dict[str, Rows]:
    out: dict[str, Rows] = defaultdict(Rows)
    for row in await conn.fetch(sql):
        out[row["robot_id"]].add(row)
    return out


@dataclass
class Dataset:
    columns: dict[str, list[Any]]
    decisions: int  # command2robot rows read
    skipped: int  # of them, with nothing to describe them

    @property
    def examples(self) -> int:
        return len(self.columns["decision_id"])


async def read(
    conn: Any, horizon_s: float = DEFAULT_HORIZON_S, label: Labeller | None = None
) -> Dataset:
    """Every decision of the database ``conn`` opens, as examples. ``label``: the targets
    are its command for each example's state (NaN where it has none), ``source`` its name,
    and what the stack decided moves to the DECIDED columns."""
    scans = await _by_robot(
        conn,
        "SELECT id, robot_id, stamp, angle_min, angle_increment, range_min, range_max, ranges"
        " FROM laser_scan"
        " ORDER BY robot_id, stamp, id",
    )
    odom = await _by_robot(
        conn,
        "SELECT id, robot_id, stamp, x, y, yaw, linear_mps, angular_rps FROM odometry"
        " ORDER BY robot_id, stamp, id",
    )
    paths = await _by_robot(
        conn,
        "SELECT id, robot_id, stamp, goal_id, target, target_x, target_y, xs, ys, length_m"
        " FROM planned_path"
        " ORDER BY robot_id, stamp, id",
    )
    hits = await _by_robot(
        conn, "SELECT id, robot_id, stamp FROM collision_event ORDER BY robot_id, stamp, id"
    )
    goals = {r["id"]: r["status"] for r in await conn.fetch("SELECT id, status FROM goal")}
    strategy = {
        r["robot_id"]: r["strategy_code"]
        for r in await conn.fetch("SELECT robot_id, strategy_code FROM active_strategy")
    }
    decisions = await conn.fetch(
        "SELECT c.id, c.robot_id, c.stamp, c.linear_mps, c.angular_rps, c.source, r.inputs"
        " FROM command2robot c LEFT JOIN command_recommendation r ON r.id = c.recommendation_id"
        " ORDER BY c.robot_id, c.stamp, c.id"
    )
    names = (*META, *FEATURES, *HISTORY_FEATURES, *TARGETS, *OUTCOMES)
    if label is not None:
        names = (*names, *DECIDED, *LATTICE)
    columns: dict[str, list[Any]] = {n: [] for n in names}
    histories: dict[str, History] = defaultdict(History)
    skipped = 0
    for d in decisions:
        robot, stamp = d["robot_id"], d["stamp"]
        raw = d["inputs"]
        inputs: dict[str, Any] = (json.loads(raw) if isinstance(raw, str) else raw) or {}
        scan = scans[robot].named(inputs, "laser_scan", stamp)
        o = odom[robot].named(inputs, "odometry", stamp)
        path = paths[robot].named(inputs, "planned_path", stamp)
        if scan is None or o is None or path is None or not path["xs"]:
            skipped += 1
            continue
        pose = (o["x"], o["y"], o["yaw"])
        sectors = sector_minima(scan["ranges"], scan["angle_min"], scan["angle_increment"])
        row = features(sectors, (o["linear_mps"], o["angular_rps"]), pose, path["xs"], path["ys"])
        end = (path["xs"][-1], path["ys"][-1])
        history = histories[robot]
        history.add(sample(o["stamp"], pose, o["linear_mps"], end, row))
        later = odom[robot].at_or_after(stamp + horizon_s)
        progress = (
            math.dist(pose[:2], end) - math.dist((later["x"], later["y"]), end)
            if later is not None
            else math.nan
        )
        crash = hits[robot].at_or_after(stamp)
        values: dict[str, Any] = {
            "decision_id": d["id"],
            "robot_id": robot,
            "stamp": stamp,
            "strategy": strategy.get(robot, ""),
            "scan_id": scan["id"],
            "odometry_id": o["id"],
            "path_id": path["id"],
            "linear_mps_cmd": d["linear_mps"],
            "angular_rps_cmd": d["angular_rps"],
            "source": d["source"] or "",
            "progress_m": progress,
            "collision": crash is not None and crash["stamp"] <= stamp + horizon_s,
            "goal_status": goals.get(path["goal_id"], ""),
            **dict(zip(FEATURES, row.tolist(), strict=True)),
            **dict(zip(HISTORY_FEATURES, history.features().tolist(), strict=True)),
        }
        if label is not None:
            values["decided_linear_mps"] = d["linear_mps"]
            values["decided_angular_rps"] = d["angular_rps"]
            values["decided_source"] = values["source"]
            said = label(robot, scan, o, path)
            values["linear_mps_cmd"], values["angular_rps_cmd"] = said or (math.nan, math.nan)
            values["source"] = label.name
            cell = label.cell if said is not None else None
            values["dwa_cell"], values["dwa_admissible"] = cell or (-1, [])
        for name, value in values.items():
            columns[name].append(value)
    return Dataset(columns, len(decisions), skipped)


def to_parquet(dataset: Dataset, path: str, meta: dict[str, str]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.table(dataset.columns)
    fields = {"pnav.features": json.dumps(list(FEATURES)), **meta}
    table = table.replace_schema_metadata({k: v for k, v in fields.items()})
    pq.write_table(table, path)


def matrix(columns: dict[str, Any], names: tuple[str, ...]) -> np.ndarray[Any, Any]:
    return np.column_stack([np.asarray(columns[n], dtype=np.float64) for n in names])

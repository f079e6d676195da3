"""The safety layer's verdict, asked before a footprint polygon's winner is recommended.

dwa admits an arc when the footprint keeps its margin at each of its roll-out's poses. A
polygon turning hard sweeps its corners between two of those poses (a turn of 4 rad/s moves
a Jackal's corner several centimetres between steps), and once inside the margin dwa admits
any arc that does not bring the outline nearer at those poses. The bridge's safety layer
judges the same command finely, along its arc for the stopping distance and through its
turn (common/sweep.py), and stops it: the robot stands, dwa chooses the same arc again at
the next scan, and recovery gives up (the Jackal's box in BARN's hard worlds).

So, for a polygon, the winner is put to the layer's own test (:func:`common.sweep.passes`,
the layer's default margin and latency, the robot's braking); if it fails, the next best
admissible arc is, and so on, up to MAX_TRIES. The disc is never vetoed: a round robot's
turn sweeps nothing, and dwa's margin already keeps its straight travel.
"""

from __future__ import annotations

import numpy as np

from common import sweep
from common.contract.records import LaserScan, Robot
from common.footprint import Footprint
from pnav_local.trajectories import BoolArray, FloatArray

# how many of the best admissible arcs are put to the test before braking instead
MAX_TRIES = 24


def winner(
    best: int,
    total: FloatArray,
    ok: BoolArray,
    v: FloatArray,
    w: FloatArray,
    scan: LaserScan,
    robot: Robot,
    footprint: Footprint,
) -> tuple[int | None, int]:
    """(the arc to recommend, how many better admissible ones the layer's test refused):
    ``best`` itself when it passes or the footprint is a disc; None when none of the
    MAX_TRIES best passes (brake)."""
    if footprint.is_disc:
        return best, 0
    returns = _near(scan, robot, footprint)
    if returns is None:
        return best, 0
    decel = robot.max_linear_accel_mps2

    judged: dict[tuple[float, float], bool] = {}

    def passes(i: int) -> bool:
        # a box's two-segment roll-outs share their first (v, w), the command tested, with
        # each other and with an arc: each command is judged once
        command = (float(v[i]), float(w[i]))
        if command not in judged:
            judged[command] = sweep.passes(
                returns, footprint, *command,
                margin_m=sweep.MARGIN_M, latency_s=sweep.LATENCY_S, decel_mps2=decel,
            )  # fmt: skip
        return judged[command]

    if passes(best):
        return best, 0
    order = np.argsort(-np.where(ok, total, -np.inf), kind="stable")
    tried = 0
    for i in order[: min(MAX_TRIES, int(ok.sum()))]:
        if passes(int(i)):
            return int(i), tried
        tried += 1
    return None, tried


def _near(scan: LaserScan, robot: Robot, footprint: Footprint) -> sweep.Returns | None:
    """The scan's returns the layer's test can meet at the robot's top speed (None: nothing
    near enough to matter, and every arc passes)."""
    top = max(robot.max_linear_mps, 0.0)
    decel = robot.max_linear_accel_mps2
    reach = (
        sweep.arc_reach(top, sweep.LATENCY_S, decel, sweep.MARGIN_M)
        + footprint.circumscribed_m
        + sweep.MARGIN_M
    )
    returns = sweep.Returns.of_ranges(
        scan.ranges.astype(np.float64), scan.angle_min, scan.angle_increment, scan.range_min
    ).within(reach)
    return returns if len(returns.xs) else None

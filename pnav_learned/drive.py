"""learned_drive: a controller scenario that drives with a model trained on the stack's own
decisions (``pnav learn train``), e.g. a policy distilled from dwa's.

Per fresh scan it computes the decision's features (pnav_learned.features: scan sectors,
odometry, the planned path's carrot and target in the robot's frame), runs the model named
by the strategy's params, and takes the velocity it predicts as a proposal that dwa's
geometry checks (pnav_learned.candidates: the nearest admissible of it and dwa's lattice, or
a brake when nothing but standing still is). It recommends that at priority 30 (dwa's: a
local controller; avoid, recovery and the safety band keep the last word, and the bridge's
safety layer judges the command as any other), with ``dwa_*`` params read as dwa reads them.
Its reason names the model, its version, its confidence, the proposal and the check's
verdict.

A model that is a classifier over dwa's lattice (``pnav learn train --target lattice``:
pnav_learned.lattice; told apart from a regression by its targets) is run instead by
:func:`from_lattice`: its TOP_K likeliest cells of the decision's window checked as one
batch, the NEXT_K next only if none passes, and dwa's own decision (pnav_local.dwa) if none
of those does; the reason then says that dwa decided.

Params: ``learned_model`` (a model registered in the ``model`` table, or a model file) and,
optionally, ``learned_model_version`` (the registered version, or the version the file must
have): pnav_learned.registry. A model file that is missing, corrupt, made for other features
or of another version is refused when loaded, logged once with the reason, and the scenario
stands down (recommends nothing) until the params, the register or the file change: the
other scenarios of the strategy go on.

What it remembers per robot (the one stop on an empty path) is an attribute of its rule,
which is one per (robot, scenario): never shared between robots.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from common.contract.planned_path import PlannedPath
from common.contract.records import LaserScan, Odometry, Robot
from common.controller_core.scenario import Command
from pnav_learned import lattice
from pnav_learned.candidates import Scene, check
from pnav_learned.features import FEATURES, FloatArray, features, sector_minima
from pnav_learned.model import DRIVE_KINDS, Model
from pnav_learned.scenario import LearnedScenario
from pnav_local import dwa
from pnav_local.dwa_params import DwaParams

PRIORITY = 30
PARAMS = "learned"  # learned_model, learned_model_version
TARGET_DIST = FEATURES.index("target_dist")
# a lattice classifier's cells put to the check a decision, as one batch: enough that one
# passes in most decisions (9 in 10 on held-out BARN worlds), few enough that the batch
# costs a small share of dwa's window; and if none passes, the next NEXT_K as another
# (then 99 in 100 pass: a batch of 18 arcs costs a tenth of dwa's decision, which the
# fallback costs)
TOP_K = 6
NEXT_K = 18


def recommend(
    model: Model,
    scan: LaserScan,
    odom: Odometry,
    robot: Robot,
    path: PlannedPath,
    label: str | None = None,
    params: DwaParams | None = None,
    polygon: Sequence[Sequence[float]] | None = None,
) -> Command:
    """The model's proposal, checked (pnav_learned.candidates): the nearest admissible of
    it and its neighbours on dwa's lattice, or a brake that says none is."""
    sectors = sector_minima(scan.ranges, scan.angle_min, scan.angle_increment)
    x = features(
        sectors,
        (odom.linear_mps, odom.angular_rps),
        (odom.x, odom.y, odom.yaw),
        path.xs,
        path.ys,
    )
    p = params or DwaParams()
    label = label or f"model {model.name} version {model.version}"
    if model.lattice:
        return from_lattice(model, x, scan, odom, robot, path, label, p, polygon)
    linear, angular, confidence = model.predict(x)
    linear = float(np.clip(linear, -robot.max_linear_mps, robot.max_linear_mps))
    angular = float(np.clip(angular, -robot.max_angular_rps, robot.max_angular_rps))
    verdict = check((linear, angular), scan, odom, robot, p, float(x[TARGET_DIST]), polygon)
    why = (
        f"learned_drive: {label}, confidence {confidence:.2f} (share of features within the"
        f" training data's range): proposed {linear:.2f} m/s, {angular:+.2f} rad/s; "
    )
    # a gap is measured exactly only below what the margin reads (clearance.gaps)
    exact = p.margin_m + 0.01
    gap = f"{verdict.gap_m:.2f} m" if verdict.gap_m < exact else f"over {exact:.2f} m"
    if verdict.rank is None:
        why += (
            f"none of the {verdict.checked} candidates checked (the proposal and its"
            " neighbours on dwa's lattice) is admissible for the footprint: brake"
        )
    elif verdict.rank == 0:
        why += f"admissible (gap {gap})"
    else:
        why += (
            f"not admissible; its neighbour {verdict.linear:.2f} m/s,"
            f" {verdict.angular:+.2f} rad/s is (rank {verdict.rank}, gap {gap},"
            f" {verdict.checked} candidates checked)"
        )
    return Command(
        verdict.linear,
        verdict.angular,
        why + p.scaled,
        {
            "planned_path": path.id,
            "model": model.name,
            "model_version": model.version,
            "proposed_linear_mps": round(linear, 4),
            "proposed_angular_rps": round(angular, 4),
            "admissible": verdict.admitted,
            "checked": verdict.checked,
        },
    )


def candidates(probs: FloatArray, v: FloatArray, w: FloatArray, k: int) -> npt.NDArray[np.int64]:
    """The ``k`` likeliest cells that are distinct moves, likeliest first: a window with no
    room for speed (or for turning) repeats its speeds (turn rates), and standing still is a
    brake, not a move."""
    order = np.argsort(-probs, kind="stable")
    rows, columns = np.divmod(order, lattice.ANGULAR)
    # the cells of a window with no room for speed are one per turn rate, and so on
    key = (rows if v[-1] > v[0] else 0) * lattice.ANGULAR + (columns if w[-1] > w[0] else 0)
    _, first = np.unique(key, return_index=True)
    first.sort()
    picked = order[first]
    moving = (v[picked] != 0.0) | (w[picked] != 0.0)
    chosen: npt.NDArray[np.int64] = picked[moving][:k].astype(np.int64)
    return chosen


def from_lattice(
    model: Model,
    x: FloatArray,
    scan: LaserScan,
    odom: Odometry,
    robot: Robot,
    path: PlannedPath,
    label: str,
    p: DwaParams,
    polygon: Sequence[Sequence[float]] | None,
) -> Command:
    """A classifier over dwa's lattice (pnav_learned.lattice): its TOP_K likeliest cells of
    this decision's window, put to dwa's check as one batch (pnav_learned.candidates.Scene),
    and only if none passes the NEXT_K next likeliest as another; the likeliest that passes
    is recommended. If none does, dwa decides (pnav_local.dwa, its whole window scored):
    what dwa would have done, and the why says so."""
    probs, confidence = model.outputs(x)
    scene = Scene(scan, odom, robot, p, float(x[TARGET_DIST]), polygon)
    v, w = lattice.grid(scene.bounds)
    ranked = candidates(probs, v, w, TOP_K + NEXT_K)
    picked = ranked[:TOP_K]
    ok, gaps = scene.admissible(v[picked], w[picked]) if len(picked) else (np.zeros(0, bool), v)
    if not ok.any() and len(ranked) > TOP_K:
        picked = ranked
        more, more_gaps = scene.admissible(v[ranked[TOP_K:]], w[ranked[TOP_K:]])
        ok, gaps = np.concatenate([ok, more]), np.concatenate([gaps, more_gaps])
    head = f"learned_drive: {label}, confidence {confidence:.2f}"
    inputs: dict[str, Any] = {
        "planned_path": path.id,
        "model": model.name,
        "model_version": model.version,
        "checked": len(picked),
    }
    if ok.any():
        r = int(np.flatnonzero(ok)[0])
        i = int(picked[r])
        exact = p.margin_m + 0.01  # a gap is measured exactly only below this
        gap = f"{gaps[r]:.2f} m" if gaps[r] < exact else f"over {exact:.2f} m"
        why = (
            f"{head} (share of features within the training data's range): dwa's lattice"
            f" cell {lattice.CELLS[i][5:]} ({probs[i]:.2f} likely), {v[i]:.2f} m/s,"
            f" {w[i]:+.2f} rad/s, admissible (gap {gap}; choice {r + 1} of the"
            f" {len(picked)} likeliest checked)"
        )
        inputs |= {"probability": round(float(probs[i]), 4), "fallback": False}
        return Command(float(v[i]), float(w[i]), why + p.scaled, inputs)
    share = float(probs[picked].sum()) if len(picked) else 0.0
    inputs |= {"probability": round(share, 4), "fallback": True}
    choice = dwa.choose(scan, odom, robot, path, p, polygon)
    said = (
        dwa.command_for(choice, path)
        if choice is not None
        else Command(0.0, 0.0, "dwa: no point of the path ahead: brake")
    )
    why = (
        f"{head}: none of the {len(picked)} likeliest cells of dwa's lattice ({share:.2f}"
        f" likely together) is admissible: fallback to dwa's own decision; {said.reason}"
    )
    return Command(said.linear, said.angular, why + p.scaled, inputs)


class LearnedDrive(LearnedScenario):
    scenario = "learned_drive"
    priority = PRIORITY
    params = PARAMS
    kind = DRIVE_KINDS

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        # this robot's memory: the empty path it already recommended its one stop on
        self.stopped_for: int | None = None

    def judge(self, scan: LaserScan, odom: Odometry | None) -> Command | None:
        found = self.model()
        path = self.path
        if found is None or path is None or odom is None:
            return None
        if path.empty:
            if self.stopped_for == path.id:
                return None
            self.stopped_for = path.id
            return Command(0.0, 0.0, f"learned_drive: no path ({path.target}): stop")
        robot = self.spec.robot
        params = DwaParams.read(self.spec.params)
        return recommend(
            found.model, scan, odom, robot, path, found.label, params, robot.footprint_polygon
        )

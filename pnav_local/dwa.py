"""dwa: a dynamic-window local controller, driving the robot along the planner's path at the
robot's own speed.

Per fresh scan it samples the velocities the robot can reach before its next decision (the
robot row's limits and accelerations), rolls each out for ``dwa_horizon_s``, drops those
that would hit what the lidar sees, and recommends the best of the rest for progress along
the path in force (``planned_path``), distance from it, heading, clearance and speed
(trajectories.py has the arithmetic). Priority 30: above the planner's own move scenarios
(10), below the avoid scenarios (50), recovery (70, the planner's) and the safety band
(safety_stop, 100, and the bridge's safety layer), which keep the last word.

Silent without a fresh scan, odometry or a path; on an empty path (the target reached,
failed or gone) it recommends one stop, so its own last command does not outlive the path.

One decision's work is bounded whatever the strategy row, the scan and the path say: at
most params.POSE_BUDGET poses rolled out, bounds.MAX_OBSTACLES hits and
bounds.MAX_PATH_POINTS path points, computed bounds.PAIRS_PER_PRODUCT pairs at a time
(docs/CONTROLLER.md, *dwa*, "Bounded work").
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import numpy.typing as npt

import pnav_local.clearance as clearance
import pnav_local.trajectories as tr
import pnav_local.veto as veto
from common.contract.planned_path import PlannedPath
from common.contract.records import LaserScan, Odometry, Robot
from common.controller_core.scenario import Command, ControllerScenario
from common.footprint import Footprint
from common.scan import readings
from pnav_local.dwa_params import POSE_BUDGET, DwaParams

PRIORITY = 30


@dataclass(frozen=True)
class Choice:
    """What one decision found: the window, the scores, and the winner (None: no
    admissible trajectory)."""

    window: tr.Window
    ok: tr.BoolArray
    scores: tr.Scores | None
    best: int | None
    local: tr.Local
    v_cap: float
    blocked: bool = False  # the path ahead runs into a lidar hit
    vetoed: int = 0  # better admissible arcs the safety layer's test refused (veto.py)
    squeezed: bool = False  # admitted with dwa_squeeze_margin_m: nothing moved with the margin


@functools.lru_cache(maxsize=8)
def _beams(angle_min: float, increment: float, count: int) -> tuple[tr.FloatArray, tr.FloatArray]:
    """Each beam's unit vector (cos, sin): the same for every scan of one lidar."""
    angles = LaserScan(
        0, "", 0.0, angle_min, increment, 0.0, 0.0, np.zeros(count, np.float32)
    ).angles()
    return np.cos(angles), np.sin(angles)


def obstacles(scan: LaserScan, reach_m: float) -> tr.FloatArray:
    """The scan's hits within ``reach_m``, robot frame (x ahead, y left), merged."""
    ranges = scan.ranges.astype(np.float64)
    cos, sin = _beams(scan.angle_min, scan.angle_increment, len(ranges))
    valid = (
        np.isfinite(ranges)
        & readings(ranges, scan.range_min)
        & (ranges <= min(scan.range_max, reach_m))
    )
    r = ranges[valid]
    return tr.merge_obstacles(np.column_stack([r * cos[valid], r * sin[valid]]))


# the last path's points as arrays, by identity: a row is followed for many decisions, and
# turning its tuples into arrays each time cost more than moving them (hashing the row too)
_last_path: list[tuple[PlannedPath, tr.FloatArray, tr.FloatArray]] = []


def _path_arrays(path: PlannedPath) -> tuple[tr.FloatArray, tr.FloatArray]:
    """The path's points as arrays (read only), made once per row object."""
    last = _last_path[0] if _last_path else None
    if last is not None and last[0] is path:
        return last[1], last[2]
    xs, ys = np.asarray(path.xs, dtype=np.float64), np.asarray(path.ys, dtype=np.float64)
    xs.flags.writeable = ys.flags.writeable = False
    _last_path[:] = [(path, xs, ys)]
    return xs, ys


def path_in_robot_frame(path: PlannedPath, odom: Odometry) -> tr.FloatArray:
    """The path's points in the frame of the robot at ``odom``."""
    xs, ys = _path_arrays(path)
    dx = xs - odom.x
    dy = ys - odom.y
    c, s = math.cos(odom.yaw), math.sin(odom.yaw)
    return np.column_stack([c * dx + s * dy, -s * dx + c * dy])


def stopping_speed(gap_m: float, lookahead_s: float, accel: float) -> float:
    """The fastest speed v with v x lookahead_s + v^2 / (2 accel) <= gap_m: what still
    stops within the gap after the lookahead (safety_stop's reach, services/controller)."""
    if accel <= 0.0:
        return gap_m / lookahead_s if lookahead_s > 0 else math.inf
    t = lookahead_s
    return accel * (math.sqrt(t * t + 2.0 * gap_m / accel) - t)


def admit(
    win: tr.Window,
    gaps: tr.FloatArray,
    start_gap: float,
    slow: npt.NDArray[np.int64],
    beyond: tr.FloatArray,
    p: DwaParams,
    accel: float,
    *,
    squeeze: bool,
) -> tuple[tr.BoolArray, bool]:
    """(the admissible trajectories, whether they were admitted with the squeeze margin):
    clear by the margin (trajectories.admissible), the slow ones ``slow`` also followed on
    (``beyond``, their gaps). ``squeeze``: a footprint polygon that can move nowhere with
    ``dwa_margin_m`` is admitted with ``dwa_squeeze_margin_m``."""

    def admitted(margin: float) -> tr.BoolArray:
        ok = tr.admissible(
            win, gaps, start_gap, margin_m=margin, accel_v=accel, delay_s=p.delay_s,
            horizon_s=p.horizon_s,
        )  # fmt: skip
        if p.min_travel_s > 0:
            # a slow arc clear for the horizon only (a few centimetres) let the Jackal creep
            # ever slower toward a corner it could not pass, never stuck long enough for
            # recovery; counted at the robot's top speed, so a slow robot (the Burger) is
            # hardly touched
            limit = min(margin, start_gap - 0.005)
            ok[slow] &= beyond.min(axis=1, initial=np.inf) >= limit  # tr.clear_for's test
        return ok

    ok = admitted(p.margin_m)
    moving = win.v > 0
    if squeeze and 0.0 < p.squeeze_margin_m < p.margin_m and not ok[moving].any():
        # a box that can go nowhere with the margin: the planner plans the centre on the
        # inscribed disc's clearance, so its path may lead through a gap the box passes
        # with less (barn_hard_001: 6 cm each side, the way out 3 to 4 cm); the margin is
        # shrunk to squeeze through rather than stand until recovery gives up, the safety
        # layer's test still put to the winner (veto.py)
        wider = admitted(p.squeeze_margin_m)
        if wider[moving].any():
            return wider, True
    return ok, False


def choose(
    scan: LaserScan,
    odom: Odometry,
    robot: Robot,
    path: PlannedPath,
    p: DwaParams,
    polygon: Sequence[Sequence[float]] | None = None,
) -> Choice | None:
    """Score the dynamic window for this scan (None: the path has no point). ``polygon``:
    the robot's footprint outline (robot frame, metres, counter-clockwise) its roll-outs
    are checked with; None: the disc of the robot's ``footprint_radius_m``."""
    top = robot.max_linear_mps
    lookahead = p.lookahead_m or max(0.8, top * (p.horizon_s + p.delay_s) + 0.3)
    local = tr.localise(path_in_robot_frame(path, odom), lookahead, p.sight_m)
    if local is None:
        return None
    radius = robot.footprint_radius_m
    foot = clearance.Footprint.of(radius, polygon)
    reach = p.obstacle_range_m or (top * (p.horizon_s + p.delay_s) + foot.reach_m + 0.5)
    points = obstacles(scan, reach)
    accel = robot.max_linear_accel_mps2
    # stop at the path's end, and stay below safety_stop's reach straight ahead: its
    # lookahead and the braking distance (v T + v^2 / 2a within the gap), or safety_stop
    # stops the robot, and from a standstill the window's best may be a loop
    v_cap = math.sqrt(2.0 * accel * max(0.0, local.remaining_m)) * 0.8
    straight = max(0.0, tr.straight_gap(points, radius) - radius - p.safety_margin_m)
    v_cap = min(v_cap, stopping_speed(straight, p.safety_lookahead_s, accel))
    # the turn rate that faces the carrot (or where the path is seen to lead, local.facing)
    # at the horizon's end: a robot a few degrees off could otherwise only overshoot (the
    # grid's steps are coarse) and stood still instead
    align = math.atan2(local.facing[1], local.facing[0]) / p.horizon_s
    win = tr.window(
        odom.linear_mps,
        odom.angular_rps,
        max_v=top,
        max_w=robot.max_angular_rps,
        accel_v=accel,
        accel_w=robot.max_angular_accel_rps2,
        dt=p.window_s,
        v_samples=p.linear_samples,
        w_samples=p.angular_samples,
        v_cap=v_cap,
        extra_w=align,
    )
    start = tr.start_pose(odom.linear_mps, odom.angular_rps, p.delay_s)
    if polygon is not None:
        win = bent_window(win, p, robot, local, start, points, foot.reach_m)
    # only what this window's arcs can come near matters to them
    near = math.hypot(start[0], start[1]) + float(win.v.max()) * p.horizon_s + foot.reach_m + 0.5
    points = points[np.hypot(points[:, 0], points[:, 1]) <= near]
    poses = tr.rollout(win, start, p.horizon_s, p.steps)
    # gaps beyond the footprint, exact up to what the margin reads (the clearance score's
    # reach is measured below, for the arcs that can still win only): the roll-outs, the
    # start and the slow arcs followed on further, in one query
    needed = p.margin_m + 0.01
    hits = clearance.Index(points, foot.reach_m + needed)
    slow, on = tr.further(win, start, p.min_travel_s * top, p.horizon_s, p.steps)
    if p.min_travel_s <= 0:
        slow = slow[:0]
    flat, spread = _distinct(win, poses, p)
    xs, ys, yaws = (
        np.concatenate([flat[k], [start[k]], on[k][: len(slow)].ravel()]) for k in range(3)
    )
    n, m = len(flat[0]), len(xs)
    near_path = radius + p.margin_m
    if foot.polygon is None:
        # a disc's gaps and the path's distances are both roots of squared distances: one
        # query for all (the path's reach is within the roll-outs'; beyond it, only "not
        # nearer than" is read, as tr.path_blocked reads it)
        dense = tr.densify(local.points)
        d2 = clearance.squared(
            np.concatenate([xs, dense[:, 0]]),
            np.concatenate([ys, dense[:, 1]]),
            hits,
            foot.reach_m + needed,
        )
        every = np.sqrt(d2[:m]) - radius
        blocked = len(dense) > 0 and bool(np.sqrt(d2[m:]).min() < near_path)
    else:
        every = clearance.gaps(xs, ys, yaws, hits, foot, needed)
        blocked = tr.path_blocked(local, hits, near_path)
    gaps = spread(every[:n])
    start_gap = float(every[n])
    beyond = every[n + 1 :].reshape(len(slow), p.steps)

    box = polygon is not None
    ok, squeezed = admit(win, gaps, start_gap, slow, beyond, p, accel, squeeze=box)
    if not ok.any():
        return Choice(win, ok, None, None, local, v_cap)
    weights = p.weights
    if blocked:
        # the path runs into what the lidar shows (the planner has not re-planned yet):
        # keeping to it is worth little, getting round toward the carrot is what counts
        weights = replace(weights, path=weights.path * p.blocked_path_factor)

    def scored(gaps: tr.FloatArray, terms: tr.Scores | None = None) -> tr.Scores:
        cap = p.clearance_cap_m
        return tr.score(
            win, poses, gaps, local, start=start, max_v=top, horizon_s=p.horizon_s,
            clearance_cap_m=cap, weights=weights, terms=terms,
        )  # fmt: skip

    # early rejection: the clearance term lies between 0 and its weight x the speed share,
    # so an arc whose total with full clearance is below another's with none cannot win;
    # only the others are measured out to the clearance cap (the winner is the same)
    bound = scored(np.full((len(gaps), 1), np.inf))
    floor = bound.total - weights.clearance * bound.clearance
    contenders = np.flatnonzero(ok & (bound.total >= floor[ok].max() - 1e-9))
    if p.clearance_cap_m > needed:
        at_cap = (poses[0][contenders], poses[1][contenders], poses[2][contenders])
        # the same index while the longer reach looks in a few more of its strips (7 at
        # most); past that, one of strips as wide as it asks (a pose's boxes stay bounded)
        wide, cap_reach = hits, foot.reach_m + p.clearance_cap_m
        if cap_reach > 3.0 * (foot.reach_m + needed):
            wide = clearance.Index(points, cap_reach)
        gaps[contenders] = clearance.gaps(*at_cap, wide, foot, p.clearance_cap_m)
    scores = scored(gaps, bound)
    top_arc = int(np.argmax(np.where(ok, scores.total, -np.inf)))
    best: int | None = top_arc
    vetoed = 0
    if polygon is not None:
        outline = Footprint.of(radius, polygon)
        best, vetoed = veto.winner(top_arc, scores.total, ok, win.v, win.w, scan, robot, outline)
    return Choice(win, ok, scores, best, local, v_cap, blocked, vetoed, squeezed)


def _distinct(
    win: tr.Window, poses: tuple[tr.FloatArray, tr.FloatArray, tr.FloatArray], p: DwaParams
) -> tuple[list[tr.FloatArray], Callable[[tr.FloatArray], tr.FloatArray]]:
    """The roll-outs' poses to measure (flat, x, y, yaw) and how to spread their gaps back
    over every pose (trajectories x steps): a two-segment roll-out's poses up to its bend
    are its straight arc's, bit for bit (tr.shared_steps), and are measured once (a box's
    window: some 8 % of its poses, a tenth of a decision's pairs)."""
    shape = poses[0].shape
    rows, arcs, shared = tr.shared_steps(win, p.horizon_s, p.steps)
    if len(rows) == 0:
        return [q.ravel() for q in poses], lambda flat: flat.reshape(shape)
    own = np.ones(shape, dtype=np.bool_)
    own[rows, :shared] = False

    def spread(flat: tr.FloatArray) -> tr.FloatArray:
        out = np.empty(shape)
        out[own] = flat
        out[rows, :shared] = out[arcs, :shared]
        return out

    return [q[own] for q in poses], spread


def bent_window(
    win: tr.Window,
    p: DwaParams,
    robot: Robot,
    local: tr.Local,
    start: tuple[float, float, float],
    points: tr.FloatArray,
    reach_m: float,
) -> tr.Window:
    """A footprint polygon's window with its two-segment roll-outs (trajectories.with_bends),
    within what the pose budget leaves (the fastest speeds' first). A disc turns in place
    wherever it fits, so "straight on, then turn" is two of its decisions; a box in a gap
    narrower than its diagonal cannot, and must see the turn coming before it commits.
    ``points``: the scan's hits (robot frame); ``reach_m``: the footprint's circumscribed
    radius. With ``dwa_bends_in_open`` 0, only the bends whose bend (where the first segment
    ends) comes within the reach and ``dwa_margin_m`` of a hit are kept (bends_needed)."""
    if p.bend_turns <= 0 or p.bend_s <= 0.0 or p.bend_s >= p.horizon_s:
        return win
    # only arcs that cover dwa_min_travel_s at top speed: a slower one is followed on (its
    # single arc) as far, which a bend's shape is not
    min_v = p.min_travel_s * robot.max_linear_mps / p.horizon_s if p.min_travel_s > 0 else 0.0
    bent = tr.with_bends(
        win, bend_s=p.bend_s, max_v=robot.max_linear_mps, max_w=robot.max_angular_rps,
        accel_v=robot.max_linear_accel_mps2, accel_w=robot.max_angular_accel_rps2,
        turns=p.bend_turns, min_v=min_v, aim=local.facing, start=start, horizon_s=p.horizon_s,
    )  # fmt: skip
    if not p.bends_in_open:
        bent = bends_needed(bent, win.arcs, start, points, reach_m + p.margin_m)
    room = POSE_BUDGET // p.steps - len(win.v)
    if bent.then_w is None or bent.then_v is None or len(bent.then_w) <= room:
        return bent
    if room <= 0:
        return win
    # the budget's rest: the last ones (squaring up, then the fastest speeds' turns)
    n = win.arcs
    keep = slice(len(bent.then_w) - room, None)
    return tr.Window(
        np.concatenate([win.v, bent.v[n:][keep]]),
        np.concatenate([win.w, bent.w[n:][keep]]),
        win.turns,
        bent.then_w[keep],
        bent.bend_s,
        bent.then_v[keep],
    )


def bends_needed(
    bent: tr.Window,
    arcs: int,
    start: tuple[float, float, float],
    points: tr.FloatArray,
    near_m: float,
) -> tr.Window:
    """``bent`` without the "straight on, then turn" roll-outs (after its first ``arcs``)
    whose bend, the pose where the straight ends, has no hit within ``near_m``: there the
    box turns in place like a disc, so the turn is a later decision's, not this one's. In
    the open such a bend won by a hair over the arcs and sent the Jackal straight on at top
    speed into a mover's wake, where dodge held it back behind the mover until the mover
    turned back into it (dynabarn_hard_000): dwa judges each scan as though nothing moved
    and dodge the motion being made, neither the bend's later turn. "Turn a little, then
    straight on" is kept: slow, and what shows a turn in place its progress."""
    if bent.then_w is None or bent.then_v is None:
        return bent
    v, w = bent.v[arcs:], bent.w[arcs:]
    sx, sy, syaw = start
    t = bent.bend_s
    turning = np.abs(w) > 1e-9
    safe_w = np.where(turning, w, 1.0)
    heading = syaw + w * t
    dx = np.where(turning, v / safe_w * (np.sin(heading) - math.sin(syaw)), v * t * math.cos(syaw))
    dy = np.where(turning, v / safe_w * (math.cos(syaw) - np.cos(heading)), v * t * math.sin(syaw))
    bx, by = sx + dx, sy + dy
    if len(points) == 0:
        keep = np.zeros(len(v), dtype=bool)
    else:
        d2 = (bx[:, None] - points[None, :, 0]) ** 2 + (by[:, None] - points[None, :, 1]) ** 2
        keep = d2.min(axis=1) <= near_m * near_m
    keep |= bent.then_w == 0.0  # squaring up
    if keep.all():
        return bent
    if not keep.any():
        return tr.Window(bent.v[:arcs], bent.w[:arcs], bent.turns)
    return tr.Window(
        np.concatenate([bent.v[:arcs], v[keep]]),
        np.concatenate([bent.w[:arcs], w[keep]]),
        bent.turns,
        bent.then_w[keep],
        bent.bend_s,
        bent.then_v[keep],
    )


def command_for(choice: Choice, path: PlannedPath, note: str = "") -> Command:
    """The winner as a command; ``note`` ends its reason (params scaled to the budget)."""
    inputs = {"planned_path": path.id}
    n, admitted = len(choice.window.v), int(choice.ok.sum())
    if choice.best is None or choice.scores is None:
        if choice.vetoed:
            reason = (
                f"dwa: the safety layer would stop each of the {choice.vetoed} best of"
                f" {admitted}/{n} admissible trajectories: brake{note}"
            )
        else:
            reason = f"dwa: none of {n} trajectories is admissible: brake{note}"
        return Command(0.0, 0.0, reason, inputs)
    i, s = choice.best, choice.scores
    win = choice.window
    v, w = float(win.v[i]), float(win.w[i])
    bend = ""
    if win.then_w is not None and i >= win.arcs:
        k = i - win.arcs
        then_v = v if win.then_v is None else float(win.then_v[k])
        then_w = float(win.then_w[k])
        bend = f" (this for {win.bend_s:.2f} s, then {then_v:.2f} m/s, {then_w:+.2f} rad/s)"
    return Command(
        v,
        w,
        f"dwa: best of {admitted}/{n} admissible trajectories: progress {s.progress[i]:+.2f},"
        f" path {s.path[i]:.2f}, heading {s.heading[i]:.2f}, clearance {s.clearance[i]:.2f},"
        f" speed {s.speed[i]:.2f}; {choice.local.remaining_m:.2f} m of path left"
        + bend
        + (" (squeezing: nothing moves with the margin)" if choice.squeezed else "")
        + (" (blocked ahead: rounding it)" if choice.blocked else "")
        + (f" ({choice.vetoed} better ones the safety layer would stop)" if choice.vetoed else "")
        + note,
        inputs,
    )


class Dwa(ControllerScenario):
    scenario = "dwa"
    priority = PRIORITY
    needs_odometry = True

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.path: PlannedPath | None = None
        self.stopped_for: int | None = None  # the empty path it has recommended a stop on

    async def data_acquisition(self) -> None:
        # the path in force, from the store's cache (read again on a planned_path note)
        self.path = await self.host.planned_path(self.spec.robot.robot_id) if self.live else None
        await super().data_acquisition()

    def footprint_polygon(self) -> Sequence[Sequence[float]] | None:
        """The outline the roll-outs are checked with (robot frame, metres, CCW): the robot
        row's ``footprint_polygon``; None: the disc of its ``footprint_radius_m``."""
        return self.spec.robot.footprint_polygon

    def judge(self, scan: LaserScan, odom: Odometry | None) -> Command | None:
        path = self.path
        if path is None or odom is None:
            return None
        if path.empty:
            if self.stopped_for == path.id:
                return None
            self.stopped_for = path.id
            return Command(
                0.0, 0.0, f"dwa: no path ({path.target}): stop", {"planned_path": path.id}
            )
        params = DwaParams.read(self.spec.params)
        choice = choose(scan, odom, self.spec.robot, path, params, self.footprint_polygon())
        return None if choice is None else command_for(choice, path, params.scaled)

"""The dynamic window: sample the velocities the robot can reach before the next decision,
roll each out as an arc, and score the arcs against the lidar and the planned path.

Pure numpy, no I/O, everything in the robot's frame at the scan (x ahead, y left). The
scenario (dwa.py) turns a scan, the odometry, the robot row and the planned_path row into
these arrays and reads the winner back; the unit tests drive the functions directly.

Per trajectory (constant linear ``v`` and angular ``w`` for the horizon, after the command
delay during which the robot keeps its measured velocity):

- **admissible** if the robot's round body stays farther than ``footprint + margin`` from
  every lidar hit along it over the whole horizon (as Nav2's DWB), or, for the window's
  slowest speed only (the brake), if it can stop before the first pose that does not
  (``v^2 / 2a`` plus the delay's travel); a robot already closer than that may still take
  any arc that does not bring it closer (turning in place always qualifies); an arc too
  slow to cover ``min_travel`` (``dwa_min_travel_s`` at top speed) within the horizon must
  also stay clear followed on that far (or half a turn), so the robot cannot creep ever
  slower toward what it cannot pass;
- **progress**: how much nearer the arc's end is to the carrot (the point ``lookahead`` m
  along the path ahead of the robot) than its start, as a share of the most the robot could
  cover in the horizon;
- **path**: the arc end's distance from the path ahead, in the same unit;
- **heading**: the angle between the robot's heading and the direction to the carrot, as a
  share of pi, averaged over the arc's poses (not its end only);
- **clearance**: the smallest gap along it (beyond the footprint), capped, as a share of the
  cap, times the speed share (room matters where the robot goes: standing still earns none);
- **speed**: ``v / max_linear``.

``score = progress_w * progress - path_w * path - heading_w * heading + clearance_w *
clearance + speed_w * speed``; the best admissible one wins.
"""

from __future__ import annotations

import bisect
import functools
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

import pnav_local.clearance as clearance
from pnav_local.bounds import MAX_OBSTACLES, MAX_PATH_POINTS, PAIRS_PER_PRODUCT, nearest, thin
from pnav_local.bounds import BoolArray as BoolArray  # the arrays' types, for the scenario
from pnav_local.bounds import FloatArray as FloatArray
from pnav_local.clearance import Footprint

# Obstacles are merged onto a grid this fine before the distance test: a 720-beam scan of a
# cluttered world has many hits a few millimetres apart, which tell nothing more.
MERGE_M = 0.04
# A box's "turn a little, then straight on" roll-outs (``with_bends``): these turn rates
# either way for the first segment (0.4 s: 6, 11 and 23 degrees), to square up to a gap.
SQUARING_RPS = (0.25, 0.5, 1.0)
# The most path vertices the line of sight is judged over (``sighted``: vertex x vertex).
SIGHT_POINTS = 128


@dataclass(frozen=True)
class Weights:
    progress: float = 1.0
    path: float = 0.6
    heading: float = 0.4
    clearance: float = 0.3
    speed: float = 0.3


@dataclass(frozen=True)
class Window:
    """The sampled velocities: ``v[i], w[i]`` for trajectory i."""

    v: FloatArray
    w: FloatArray
    # a grid's angular samples per speed (w the faster index, the same w's for every
    # speed): the roll-out then takes one sine and cosine per w, not per trajectory; 0: any
    turns: int = 0
    # two-segment trajectories (:func:`with_bends`), after the single arcs: trajectory i >=
    # ``arcs`` holds (v[i], w[i]) for ``bend_s``, then (then_v[i - arcs], then_w[i - arcs]).
    # The command is always (v[i], w[i]): the first segment.
    then_w: FloatArray | None = None
    bend_s: float = 0.0
    then_v: FloatArray | None = None  # the second segment's speeds (None: the first's)

    @property
    def arcs(self) -> int:
        """How many of the trajectories are single arcs (the first ones)."""
        return len(self.v) if self.then_w is None else len(self.v) - len(self.then_w)


def window(
    v0: float,
    w0: float,
    *,
    max_v: float,
    max_w: float,
    accel_v: float,
    accel_w: float,
    dt: float,
    v_samples: int,
    w_samples: int,
    v_cap: float | None = None,
    extra_w: float | None = None,
) -> Window:
    """The dynamic window around the measured (v0, w0): what ``dt`` of acceleration reaches,
    within the robot's limits (forward only: backing up is recovery's), as a grid. ``v_cap``
    lowers the top speed (the path's end is near). The slowest speed reachable and
    ``w = 0`` are always among the samples, so there is a brake and a straight line, and
    ``extra_w`` (within reach) too: the turn rate that faces the carrot."""
    top = max_v if v_cap is None else max(0.0, min(max_v, v_cap))
    v_low = min(max(0.0, v0 - accel_v * dt), top)
    v_high = min(top, max(0.0, v0) + accel_v * dt)
    w_low = max(-max_w, w0 - accel_w * dt)
    w_high = min(max_w, w0 + accel_w * dt)
    vs = np.linspace(v_low, max(v_low, v_high), max(1, v_samples))
    # a few dozen samples: the two insertions are list work, not four numpy calls each
    ws = np.linspace(min(w_low, w_high), max(w_low, w_high), max(1, w_samples)).tolist()
    for extra in (0.0, extra_w):
        if extra is not None and w_low <= extra <= w_high and extra not in ws:
            bisect.insort(ws, extra)
    # v over w, w fastest: what a meshgrid ("ij") of the unique speeds raveled gives
    vs = np.unique(vs) if vs[-1] != vs[0] else vs[:1]
    return Window(np.repeat(vs, len(ws)), np.tile(np.array(ws), len(vs)), len(ws))


def with_bends(
    win: Window,
    *,
    bend_s: float,
    max_v: float,
    max_w: float,
    accel_v: float,
    accel_w: float,
    turns: int,
    min_v: float,
    aim: tuple[float, float] | None = None,
    start: tuple[float, float, float] = (0.0, 0.0, 0.0),
    horizon_s: float = 0.0,
) -> Window:
    """``win`` with two-segment trajectories added after its arcs: at each of its speeds of
    at least ``min_v`` (and above 0), straight on (the window's turn rate nearest 0) for
    ``bend_s``, then a turn at the same speed for the rest of the horizon: ``turns`` rates
    spread evenly over ``[-max_w, max_w]`` without 0, and the rate that faces ``aim`` at
    the horizon's end from where the straight ends (the window's carrot-facing rate, one
    segment later); each within what ``accel_w`` reaches from the first's in ``bend_s``.

    One arc for the whole horizon cannot say "straight through this gap, then turn where
    the path turns": a box leaving a gap 0.6 m wide whose path turns just past it found
    only an arc into the pocket beside it (barn_hard_001, docs/CONTROLLER.md, *dwa*)."""
    if turns <= 0 or bend_s <= 0.0 or horizon_s <= bend_s or len(win.v) == 0:
        return win
    if win.then_w is not None:
        return win
    w_low, w_high = float(win.w.min()), float(win.w.max())
    w1 = min(max(0.0, w_low), w_high)
    lo, hi = w1 - accel_w * bend_s, w1 + accel_w * bend_s
    half = max(turns // 2, 1)
    side = np.linspace(max_w / half, max_w, half)
    rates = np.concatenate([-side[::-1], side]).tolist() if turns > 1 else [max_w]
    base = [r for r in rates if lo - 1e-9 <= r <= hi + 1e-9]
    sx, sy, syaw = start
    vs: list[float] = []
    then: list[float] = []
    for v in np.unique(win.v).tolist():
        if v < min_v or v <= 1e-6:
            continue
        extra = list(base)
        if aim is not None:
            # from where the straight ends, the rate that faces the aim at the horizon's end
            ex = sx + math.cos(syaw) * v * bend_s
            ey = sy + math.sin(syaw) * v * bend_s
            bearing = math.atan2(aim[1] - ey, aim[0] - ex) - syaw - w1 * bend_s
            rate = min(
                max(math.remainder(bearing, 2.0 * math.pi) / (horizon_s - bend_s), -max_w), max_w
            )
            if lo <= rate <= hi and all(abs(rate - r) > 1e-6 for r in base):
                extra.append(rate)
        vs.extend([v] * len(extra))
        then.extend(extra)
    first_w = [w1] * len(vs)
    then_v = list(vs)
    # turn a little, then straight on: squaring up to a gap the box passes only square
    v0 = float(win.v.min())
    rest = horizon_s - bend_s
    onward = max(0.25 * max_v, min_v * horizon_s / rest)
    for spin in SQUARING_RPS:
        for w in (-spin, spin):
            if w_low <= w <= w_high and abs(onward - v0) <= accel_v * bend_s + 1e-9:
                vs.append(v0)
                first_w.append(w)
                then_v.append(onward)
                then.append(0.0)
    if not vs:
        return win
    v_all = np.concatenate([win.v, np.array(vs)])
    w_all = np.concatenate([win.w, np.array(first_w)])
    return Window(v_all, w_all, win.turns, np.array(then), bend_s, np.array(then_v))


def start_pose(v0: float, w0: float, delay_s: float) -> tuple[float, float, float]:
    """Where the robot is when a command sent now takes effect: ``delay_s`` at (v0, w0)."""
    # arcs' arithmetic on scalars (a numpy call costs more than the sums)
    yaw = w0 * delay_s
    if abs(w0) < 1e-6:
        return v0 * delay_s, 0.0, yaw
    return v0 / w0 * math.sin(yaw), v0 / w0 * (1.0 - math.cos(yaw)), yaw


def arcs(
    v: FloatArray, w: FloatArray, times: FloatArray, turns: int = 0
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Poses (x, y, yaw), each trajectories x times, of constant-velocity arcs from the
    origin facing +x. ``turns``: ``w`` repeats every ``turns`` trajectories (Window.turns)."""
    t = times[None, :]
    straight = np.abs(w) < 1e-6
    radius = v[:, None] / np.where(straight, 1.0, w)[:, None]
    if turns > 0 and len(w) % turns == 0 and len(w) > turns:
        # the same products, sines and cosines as below, taken once per w and broadcast
        yaw_w = w[:turns, None] * t
        shape = (len(w) // turns, turns, len(times))
        yaw = np.broadcast_to(yaw_w, shape).reshape(len(w), len(times))
        x = (radius.reshape(shape[0], turns, 1) * np.sin(yaw_w)).reshape(yaw.shape)
        y = (radius.reshape(shape[0], turns, 1) * (1.0 - np.cos(yaw_w))).reshape(yaw.shape)
    else:
        yaw = w[:, None] * t
        x = radius * np.sin(yaw)
        y = radius * (1.0 - np.cos(yaw))
    if straight.any():
        x[straight] = (v[:, None] * t)[straight]
        y[straight] = 0.0
    return x, y, yaw


def rollout(
    win: Window, start: tuple[float, float, float], horizon_s: float, steps: int
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Every sampled trajectory's poses at ``steps`` instants over the horizon, from ``start``
    (the window's two-segment trajectories after its arcs: :func:`with_bends`)."""
    times = _times(horizon_s, steps)
    n = win.arcs
    x, y, yaw = arcs(win.v[:n], win.w[:n], times, win.turns)
    if win.then_w is not None and len(win.then_w):
        then_v = win.v[n:] if win.then_v is None else win.then_v
        bx, by, byaw = bends(win.v[n:], win.w[n:], then_v, win.then_w, win.bend_s, times)
        x, y, yaw = np.vstack([x, bx]), np.vstack([y, by]), np.vstack([yaw, byaw])
    sx, sy, syaw = start
    c, s = math.cos(syaw), math.sin(syaw)
    return sx + c * x - s * y, sy + s * x + c * y, syaw + yaw


def shared_steps(
    win: Window, horizon_s: float, steps: int
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], int]:
    """(the two-segment trajectories whose first segment is one of the window's arcs, those
    arcs, how many of the first instants they share): the instants up to ``bend_s``, where
    :func:`rollout` gives both the same poses bit for bit (the second arc adds exact zeros
    before the bend). Nothing shared: empty arrays and 0."""
    none = np.zeros(0, dtype=np.int64)
    if win.then_w is None or len(win.then_w) == 0:
        return none, none, 0
    shared = int(np.count_nonzero(_times(horizon_s, steps) <= win.bend_s))
    if shared == 0:
        return none, none, 0
    n = win.arcs
    arc_of = {
        vw: i for i, vw in enumerate(zip(win.v[:n].tolist(), win.w[:n].tolist(), strict=True))
    }
    rows: list[int] = []
    arcs: list[int] = []
    for j, vw in enumerate(zip(win.v[n:].tolist(), win.w[n:].tolist(), strict=True)):
        i = arc_of.get(vw)
        if i is not None:
            rows.append(n + j)
            arcs.append(i)
    return np.array(rows, dtype=np.int64), np.array(arcs, dtype=np.int64), shared


def bends(
    v1: FloatArray,
    w1: FloatArray,
    v2: FloatArray,
    w2: FloatArray,
    bend_s: float,
    times: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Poses (x, y, yaw), each trajectory x times, from the origin facing +x: the arc
    (v1, w1) up to ``bend_s``, then the arc (v2, w2) from where it ended."""
    first = np.minimum(times, bend_s)
    x1, y1, yaw1 = arcs(v1, w1, first)
    after = np.maximum(times - bend_s, 0.0)
    x2, y2, yaw2 = arcs(v2, w2, after)
    # the second arc placed at the first's end, turned by its heading there
    c, s = np.cos(yaw1), np.sin(yaw1)
    return x1 + c * x2 - s * y2, y1 + s * x2 + c * y2, yaw1 + yaw2


@functools.lru_cache(maxsize=8)
def _times(horizon_s: float, steps: int) -> FloatArray:
    """The roll-out's instants: the same for every decision of one params row (read only)."""
    times = np.linspace(horizon_s / steps, horizon_s, steps)
    times.flags.writeable = False
    return times


def merge_obstacles(points: FloatArray, cell_m: float = MERGE_M) -> FloatArray:
    """One point per ``cell_m`` grid cell (the first of each)."""
    if len(points) == 0:
        return points
    cells = np.floor(points / cell_m).astype(np.int64)
    key = cells[:, 0] * 1_000_003 + cells[:, 1]  # one integer per cell: a 1-D unique
    _, first = np.unique(key, return_index=True)
    merged: FloatArray = points[np.sort(first)]
    return nearest(merged, MAX_OBSTACLES)


def distances(xs: FloatArray, ys: FloatArray, obstacles: FloatArray) -> FloatArray:
    """Per pose, the distance to the nearest obstacle point (inf with none): every point
    looked at (the roll-outs use clearance.gaps, which looks near each pose only)."""
    return clearance.gaps(xs, ys, None, obstacles, Footprint(0.0), math.inf)


def admissible(
    win: Window,
    gaps: FloatArray,
    start_gap: float,
    *,
    margin_m: float,
    accel_v: float,
    delay_s: float,
    horizon_s: float,
) -> BoolArray:
    """Per trajectory: its footprint keeps ``margin`` from every obstacle over the horizon,
    or it is at the window's slowest speed and can brake before the first pose that does
    not. ``gaps``: trajectories x steps gaps beyond the footprint (clearance.gaps)."""
    # already inside the margin: any arc that does not bring it closer
    limit = min(margin_m, start_gap - 0.005)
    hit = gaps < limit
    steps = gaps.shape[1]
    first = np.where(hit.any(axis=1), hit.argmax(axis=1), steps)
    travel = np.abs(win.v) * horizon_s * (first / steps)  # arc length to the first hit
    brake = win.v**2 / (2.0 * accel_v) + np.abs(win.v) * delay_s
    # Only the window's slowest speed may head for a hit it can brake before (it is the
    # brake); a faster one that needs braking is no plan.
    slowest = win.v <= win.v.min() + 1e-9
    out: BoolArray = (first == steps) | (slowest & (brake < travel))
    return out


@dataclass(frozen=True)
class Local:
    """The planned path in the robot's frame, near the robot."""

    points: FloatArray  # the path's vertices from the robot's projection on, in order
    carrot: tuple[float, float]  # ``lookahead`` along the path ahead
    remaining_m: float  # from the projection to the path's end
    # where the robot should face: the carrot, or where the path bends out of sight before
    # it, that far along the line of sight (:func:`sighted`); None: the carrot
    aim: tuple[float, float] | None = None

    @property
    def facing(self) -> tuple[float, float]:
        """The point the heading term and the turn toward the path look at."""
        return self.carrot if self.aim is None else self.aim


def localise(path_xy: FloatArray, lookahead_m: float, sight_m: float = 0.0) -> Local | None:
    """The path (robot frame, n x 2) from the robot's projection on it: the vertices ahead
    up to the carrot, the carrot, and the length left; with ``sight_m`` > 0, the aim
    (:func:`sighted`). None for fewer than one point."""
    if len(path_xy) == 0:
        return None
    if len(path_xy) == 1:
        p = (float(path_xy[0, 0]), float(path_xy[0, 1]))
        return Local(path_xy.copy(), p, math.hypot(*p))
    a, b = path_xy[:-1], path_xy[1:]
    ab = b - a
    length2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12)
    t = np.clip(np.einsum("ij,ij->i", -a, ab) / length2, 0.0, 1.0)
    proj = a + ab * t[:, None]
    seg = int(np.argmin(np.hypot(proj[:, 0], proj[:, 1])))  # the first of equals
    ahead = np.vstack([proj[seg], path_xy[seg + 1 :]])
    steps = np.hypot(*np.diff(ahead, axis=0).T)
    cumulative = np.concatenate([[0.0], np.cumsum(steps)])
    remaining = float(cumulative[-1])
    if remaining <= lookahead_m:
        carrot = ahead[-1]
        kept = ahead
    else:
        k = int(np.searchsorted(cumulative, lookahead_m))  # cumulative[k-1] < L <= [k]
        f = (lookahead_m - cumulative[k - 1]) / max(steps[k - 1], 1e-12)
        carrot = ahead[k - 1] + f * (ahead[k] - ahead[k - 1])
        kept = np.vstack([ahead[:k], carrot])
    kept = thin(kept, MAX_PATH_POINTS)
    end = (float(carrot[0]), float(carrot[1]))
    aim = sighted(kept, sight_m) if sight_m > 0.0 else None
    return Local(kept, end, remaining, None if aim == end else aim)


def sighted(points: FloatArray, sight_m: float) -> tuple[float, float]:
    """Where to face along the path ``points`` (robot frame, from the robot's projection to
    the carrot): the carrot while the straight line from the robot to it passes within
    ``sight_m`` of every vertex between; else the farthest point along the path whose line
    does, moved out along that line to the carrot's distance (a direction to face, as far
    off as the carrot).

    A carrot far along a path that winds through clutter lies behind what the path goes
    round: facing it, the Jackal stood turned toward a gap it could not pass (every arc
    forward inadmissible, standing still the best score) while the path led the other way
    (BARN hard worlds, docs/CONTROLLER.md, *dwa*)."""
    carrot = points[-1]
    # the projection itself is where the robot is, not a bend; a vertex x vertex product,
    # so at most SIGHT_POINTS of them (bounded work, as every other product here)
    ahead = thin(points[1:], SIGHT_POINTS)
    n = len(ahead)
    end = (float(carrot[0]), float(carrot[1]))
    if n < 2:
        return end
    # deviation[k, j]: vertex j's distance from the line robot -> vertex k (j < k counts)
    k2 = np.maximum(np.einsum("ij,ij->i", ahead, ahead), 1e-18)
    t = np.clip(ahead @ ahead.T / k2[:, None], 0.0, 1.0)  # [k, j]: j projected on 0 -> k
    dx = ahead[None, :, 0] - t * ahead[:, None, 0]
    dy = ahead[None, :, 1] - t * ahead[:, None, 1]
    before = np.tri(n, n, -1, dtype=bool)
    worst = np.where(before, dx * dx + dy * dy, 0.0).max(axis=1)
    out = np.flatnonzero(worst > sight_m * sight_m)
    if len(out) == 0:
        return end
    k = int(out[0])  # in sight up to vertex k - 1 (k >= 1: vertex 0 is always in sight)
    a, b = ahead[k - 1], ahead[k]
    # the farthest point of the leg a -> b still in sight: a few fractions along it
    fractions = np.linspace(0.0, 1.0, 17)
    q = a[None, :] + fractions[:, None] * (b - a)[None, :]
    q2 = np.maximum(np.einsum("ij,ij->i", q, q), 1e-18)
    prior = ahead[:k]
    tq = np.clip(q @ prior.T / q2[:, None], 0.0, 1.0)
    ex = prior[None, :, 0] - tq * q[:, None, 0]
    ey = prior[None, :, 1] - tq * q[:, None, 1]
    seen = (ex * ex + ey * ey).max(axis=1) <= sight_m * sight_m
    point = q[int(np.flatnonzero(seen)[-1])] if seen.any() else a
    reach = math.hypot(*point)
    if reach < 1e-9:
        return end
    scale = max(math.hypot(*end), reach) / reach
    return float(point[0] * scale), float(point[1] * scale)


def densify(points: FloatArray, step_m: float = 0.05) -> FloatArray:
    """The polyline ``points`` as points at most ``step_m`` apart (its vertices kept), or
    farther apart where that would make more than MAX_PATH_POINTS (a long path)."""
    if len(points) < 2:
        return points
    points = thin(points, MAX_PATH_POINTS)
    legs = np.diff(points, axis=0)
    lengths = np.hypot(legs[:, 0], legs[:, 1])
    step_m = max(step_m, float(lengths.sum()) / MAX_PATH_POINTS)
    # every leg cut into n equal parts, their ends k / n along it (k = 1..n), all at once
    n = np.maximum(1, np.ceil(lengths / step_m)).astype(np.int64)
    leg = np.repeat(np.arange(len(n)), n)
    k = np.arange(1, int(n.sum()) + 1) - np.repeat(np.cumsum(n) - n, n)
    t = (k / n[leg])[:, None]
    dense: FloatArray = np.vstack([points[:1], points[:-1][leg] + t * legs[leg]])
    return dense


def path_blocked(local: Local, obstacles: FloatArray | clearance.Index, clearance_m: float) -> bool:
    """Whether the path ahead, up to the carrot, runs within ``clearance_m`` of a hit: the
    planner has not yet planned round something the lidar shows."""
    dense = densify(local.points)
    if len(dense) == 0:
        return False
    near = clearance.gaps(dense[:, 0], dense[:, 1], None, obstacles, Footprint(0.0), clearance_m)
    return bool(near.min() < clearance_m)


def to_path(xs: FloatArray, ys: FloatArray, points: FloatArray) -> FloatArray:
    """Per (x, y), its distance to the polyline ``points``."""
    if len(points) == 1:
        single: FloatArray = np.hypot(xs - points[0, 0], ys - points[0, 1])
        return single
    a, b = points[:-1], points[1:]
    ab = b - a
    length2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12)
    rows = max(1, PAIRS_PER_PRODUCT // len(a))  # memory bounded, however long the path
    out: FloatArray = np.empty(len(xs), dtype=np.float64)
    abx, aby = ab[None, :, 0], ab[None, :, 1]
    for i in range(0, len(xs), rows):
        # the same arithmetic as rx - t ab etc., in place: a few arrays, not a dozen
        rx = xs[i : i + rows, None] - a[None, :, 0]
        ry = ys[i : i + rows, None] - a[None, :, 1]
        t = rx * abx
        tmp = ry * aby
        t += tmp
        t /= length2[None, :]
        np.clip(t, 0.0, 1.0, out=t)
        rx -= np.multiply(t, abx, out=tmp)  # dx
        ry -= np.multiply(t, aby, out=tmp)  # dy
        rx *= rx
        ry *= ry
        rx += ry
        out[i : i + rows] = np.sqrt(rx.min(axis=1))  # np.hypot: slower
    return out


@dataclass(frozen=True)
class Scores:
    """Per trajectory, each term (before weights) and the total."""

    progress: FloatArray
    path: FloatArray
    heading: FloatArray
    clearance: FloatArray
    speed: FloatArray
    total: FloatArray


def score(
    win: Window,
    poses: tuple[FloatArray, FloatArray, FloatArray],
    gaps: FloatArray,
    local: Local,
    *,
    start: tuple[float, float, float],
    max_v: float,
    horizon_s: float,
    clearance_cap_m: float,
    weights: Weights,
    terms: Scores | None = None,
) -> Scores:
    """Every term of every trajectory (see the module's docstring). ``terms``: the same
    trajectories scored before with other gaps, whose other terms are taken as they are."""
    speed = win.v / max(max_v, 1e-6)
    # room counts where the robot goes: weighted by the speed share, so that standing
    # still (all the room it has now, no progress) never wins on clearance alone
    gap = np.clip(gaps.min(axis=1), 0.0, clearance_cap_m) / clearance_cap_m * speed
    if terms is None:
        terms = _terms(win, poses, local, start=start, max_v=max_v, horizon_s=horizon_s)
    progress, path, heading = terms.progress, terms.path, terms.heading
    total = (
        weights.progress * progress
        - weights.path * path
        - weights.heading * heading
        + weights.clearance * gap
        + weights.speed * speed
    )
    return Scores(progress, path, heading, gap, speed, total)


def _terms(
    win: Window,
    poses: tuple[FloatArray, FloatArray, FloatArray],
    local: Local,
    *,
    start: tuple[float, float, float],
    max_v: float,
    horizon_s: float,
) -> Scores:
    """The terms that do not depend on the gaps (clearance, speed and total left empty)."""
    xs, ys, yaws = poses
    ex, ey = xs[:, -1], ys[:, -1]
    cx, cy = local.carrot
    reach = max(max_v * horizon_s, 1e-6)
    before = math.hypot(cx - start[0], cy - start[1])
    progress = (before - np.hypot(cx - ex, cy - ey)) / reach
    path = to_path(ex, ey, local.points) / reach
    cx, cy = local.facing  # the heading looks where the path can be seen to lead
    # the heading along the whole arc, not at its end only: a loop that swings far off
    # and comes back facing the carrot is no better than it is; a turn in place toward the
    # carrot is better than standing still, even if it overshoots a little
    ox, oy = cx - xs, cy - ys
    # wrapped to [-pi, pi) by a remainder: one transcendental per pose instead of three
    # (atan2 of its sine and cosine), the same to a few ulps
    bearing = np.arctan2(oy, ox) - yaws
    along = np.abs(np.remainder(bearing + math.pi, 2.0 * math.pi) - math.pi) / math.pi
    # close to the carrot the bearing means little (the carrot is the path's end)
    along = np.where(ox * ox + oy * oy < (0.1 * reach) ** 2, 0.0, along)
    heading = along.mean(axis=1)
    none = np.zeros(0)
    return Scores(progress, path, heading, none, none, none)


def clear_for(
    win: Window,
    start: tuple[float, float, float],
    obstacles: FloatArray | clearance.Index,
    travel_m: float,
    horizon_s: float,
    steps: int,
    limit_m: float,
    footprint: Footprint,
) -> BoolArray:
    """Per trajectory: whether its arc, followed on until it has covered ``travel_m`` (or
    turned half a circle, or for the horizon if that is longer), keeps its footprint
    ``limit_m`` from every obstacle. Arcs that cover ``travel_m`` within the horizon and
    turns in place pass (``admissible`` judged them); slower ones are rolled out further."""
    out: BoolArray = np.ones(len(win.v), dtype=np.bool_)
    slow, (xs, ys, yaws) = further(win, start, travel_m, horizon_s, steps)
    if len(slow):
        gaps = clearance.gaps(xs, ys, yaws, obstacles, footprint, limit_m)
        out[slow] = gaps.min(axis=1) >= limit_m
    return out


def further(
    win: Window, start: tuple[float, float, float], travel_m: float, horizon_s: float, steps: int
) -> tuple[npt.NDArray[np.int64], tuple[FloatArray, FloatArray, FloatArray]]:
    """The trajectories too slow to cover ``travel_m`` within the horizon (indices), and
    their poses followed on that far (or half a turn, or the horizon if longer): what
    ``clear_for`` tests."""
    v = np.abs(win.v)
    slow = np.flatnonzero((v * horizon_s < travel_m) & (v > 1e-6))
    if len(slow) == 0:  # the usual case at speed: a dozen numpy calls on nothing spared
        none = np.zeros((0, steps))
        return slow, (none, none, none)
    vs, ws = win.v[slow], win.w[slow]
    turn_s = np.where(np.abs(ws) > 1e-6, math.pi / np.maximum(np.abs(ws), 1e-6), np.inf)
    end_s = np.maximum(np.minimum(travel_m / v[slow], turn_s), horizon_s)
    t = end_s[:, None] * np.linspace(1.0 / steps, 1.0, steps)[None, :]
    w = ws[:, None]
    straight = np.abs(w) < 1e-6
    safe_w = np.where(straight, 1.0, w)
    x = np.where(straight, vs[:, None] * t, vs[:, None] / safe_w * np.sin(w * t))
    y = np.where(straight, 0.0, vs[:, None] / safe_w * (1.0 - np.cos(w * t)))
    sx, sy, syaw = start
    c, s = math.cos(syaw), math.sin(syaw)
    return slow, (sx + c * x - s * y, sy + s * x + c * y, syaw + w * t)


def straight_gap(obstacles: FloatArray, radius_m: float) -> float:
    """Distance ahead to the first obstacle in the corridor the round body sweeps driving
    straight on (inf with none): what safety_stop measures."""
    if len(obstacles) == 0:
        return math.inf
    ahead = (obstacles[:, 0] > 0.0) & (np.abs(obstacles[:, 1]) < radius_m)
    return float(np.hypot(*obstacles[ahead].T).min()) if ahead.any() else math.inf

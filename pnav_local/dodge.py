"""dodge: keep out of the way of obstacles that move.

Nothing else in the stack knows that an obstacle moves: dwa and safety_stop judge each scan
as though everything in it stood still. dodge follows the small objects of a robot's scans
from one scan to the next (tracks.py: clusters, matched, each one's velocity in the world
frame from the odometry), and per fresh scan predicts, for the next ``threats.HORIZON_S``,
whether the robot meets a moving one doing what it is about to do (keeping its measured
velocity, or speeding up to its top speed on the same turn: what a local controller does
on a clear way), or would be stopped by safety_stop for one crossing its swept way
(threats.py). If not, it says nothing. If so, it recommends the evasive motion that meets no
mover within the horizon, keeps clear of the static hits and out of safety_stop's reach,
the fastest forward one first: slower (yield before crossing a mover's line), a stop, a swerve,
or driving on or backing out of a standing robot's spot when a mover is heading at it; if
every motion meets a mover, the one that meets it latest. Its reason names the mover's
track, its velocity and the time to collision.

Priority 90: above dwa (30), avoid (50) and the planner's recovery (70), below the safety
band (safety_stop, 100, and the bridge's safety layer, which still check every command
against the scan in the direction of travel). Its recommendations live a few scan periods
(``ttl_s``), not the usual 0.5 s, so a yield ends when its threat does.

Deterministic (the tracks follow the scans alone) and bounded (tracks.MAX_CLUSTERS,
tracks.MAX_TRACKS, threats' fixed motions and threats.MAX_STATIC hits).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from common.contract.planned_path import PlannedPath
from common.contract.records import LaserScan, Odometry, Robot
from common.controller_core.params import number
from common.controller_core.scenario import Command, ControllerScenario, Key, ScenarioSpec
from common.engine import Behaviour
from pnav_local import threats
from pnav_local.tracks import REACH_M, Tracker, robot_pose

PRIORITY = 90
MIN_TTL_S = 0.1
MAX_TTL_S = 0.5
TTL_PERIODS = 3.0  # a recommendation lives this many scan periods (within the two above)
BEHIND_DEG = 30.0  # backing out needs beams within this of straight behind
STANDING_MPS = 0.05
CARROT_M = 2.0  # evasive motions are judged by their progress toward the path this far on
_RANGE_TOLERANCE_M = 1e-4


def movers_in_robot_frame(
    tracker: Tracker, pose: tuple[float, float, float]
) -> list[threats.Mover]:
    """The moving tracks (seen in the newest scan, or hidden a moment: predicted on), in the
    robot's frame at the newest scan."""
    ox, oy, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    out = []
    now = tracker.last_t if tracker.last_t is not None else 0.0
    for k in tracker.movers():
        x, y = k.at(now)
        dx, dy = x - ox, y - oy
        out.append(
            threats.Mover(
                k.id,
                c * dx + s * dy,
                -s * dx + c * dy,
                c * k.vx + s * k.vy,
                -s * k.vx + c * k.vy,
                k.radius,
            )
        )
    return out


def static_hits(scan: LaserScan, tracker: Tracker) -> tuple[np.ndarray[Any, Any], bool]:
    """The scan's hits within reach that are not on a moving track (robot frame), and
    whether the lidar sees behind the robot."""
    ranges = scan.ranges.astype(np.float64)
    angles = scan.angles()
    valid = (
        np.isfinite(ranges)
        & (ranges >= scan.range_min - _RANGE_TOLERANCE_M)
        & (ranges <= min(scan.range_max, REACH_M))
    )
    for k in tracker.moving():
        valid[k.beams[0] : k.beams[1] + 1] = False
    r, a = ranges[valid], angles[valid]
    pts = threats.static_points(np.column_stack([r * np.cos(a), r * np.sin(a)]))
    behind = bool((np.abs(angles) >= math.radians(180.0 - BEHIND_DEG)).any())
    return pts, behind


def path_ahead(path: PlannedPath | None, pose: tuple[float, float, float]) -> tuple[float, float]:
    """The unit direction (robot frame at ``pose``) toward the point ``CARROT_M`` along the
    path from its point nearest the robot; straight ahead without a path (or at its end)."""
    if path is None or path.empty:
        return (1.0, 0.0)
    xs, ys = np.asarray(path.xs, dtype=np.float64), np.asarray(path.ys, dtype=np.float64)
    # the nearest point of the path (on its segments), then CARROT_M on along it
    x, y, i = float(xs[0]), float(ys[0]), 0
    if len(xs) > 1:
        ex, ey = np.diff(xs), np.diff(ys)
        lengths = np.maximum(ex * ex + ey * ey, 1e-12)
        f = np.clip(((pose[0] - xs[:-1]) * ex + (pose[1] - ys[:-1]) * ey) / lengths, 0.0, 1.0)
        px, py = xs[:-1] + f * ex, ys[:-1] + f * ey
        i = int(np.argmin(np.hypot(px - pose[0], py - pose[1])))
        x, y = float(px[i]), float(py[i])
    left = CARROT_M
    for j in range(i + 1, len(xs)):
        step = math.hypot(float(xs[j]) - x, float(ys[j]) - y)
        if step >= left:
            f_j = left / step
            x, y = x + f_j * (float(xs[j]) - x), y + f_j * (float(ys[j]) - y)
            break
        left -= step
        x, y = float(xs[j]), float(ys[j])
    dx, dy = x - pose[0], y - pose[1]
    d = math.hypot(dx, dy)
    if d < 0.1:
        return (1.0, 0.0)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return ((c * dx + s * dy) / d, (-s * dx + c * dy) / d)


def stop_reach(params: Mapping[str, Any]) -> threats.StopReach:
    """safety_stop's reach as the strategy's params set it (the same keys and bounds)."""
    d = threats.StopReach()
    return threats.StopReach(
        margin_m=number(params, "safety_margin_m", d.margin_m, high=2.0),
        lookahead_s=number(params, "safety_lookahead_s", d.lookahead_s, high=5.0),
    )


def decide_for(
    tracker: Tracker,
    scan: LaserScan,
    odom: Odometry,
    robot: Robot,
    path: PlannedPath | None = None,
    params: Mapping[str, Any] | None = None,
) -> Command | None:
    """Update the tracks with the scan; the evasive command, or None when no mover threatens
    what the robot is about to do. ``path``: the route in force, which evasive motions make
    progress along (none: straight ahead); ``params``: the strategy's (safety_stop's reach,
    which no evasion may enter)."""
    tracker.update(scan, odom)
    pose = robot_pose(scan, odom)
    movers = movers_in_robot_frame(tracker, pose)
    if not movers:
        return None
    v0, w0 = odom.linear_mps, odom.angular_rps
    reach = stop_reach(params or {})
    threat = threats.expected(v0, w0, robot, movers, reach)
    if math.isinf(threat.threat):
        return None
    points, behind = static_hits(scan, tracker)
    choice = threats.choose(v0, w0, robot, movers, points, behind, path_ahead(path, pose), reach)
    contact = threat.ttc <= threat.stop
    mover = next(m for m in movers if m.track == (threat.mover if contact else threat.stop_mover))
    if abs(v0) < STANDING_MPS:
        act = "step out of its way" if choice.v != 0.0 else "stand"
    elif choice.v < v0 - 0.05:
        act = "yield" if choice.v >= 0 else "back out"
    else:
        act = "keep clear"
    after = "meets none" if math.isinf(choice.ttc) else f"meets one in {choice.ttc:.1f} s"
    what = (
        f"contact in {threat.ttc:.1f} s"
        if contact
        else f"in safety_stop's reach in {threat.stop:.1f} s"
    )
    reason = (
        f"dodge: mover track {mover.track} at ({mover.x:+.2f}, {mover.y:+.2f}) m moving "
        f"{math.hypot(mover.vx, mover.vy):.2f} m/s toward "
        f"{math.degrees(math.atan2(mover.vy, mover.vx)):+.0f} deg: {what} at {threat.v:.2f} "
        f"m/s; {act}: {choice.v:.2f} m/s, {choice.w:+.2f} rad/s ({after} within "
        f"{threats.HORIZON_S:g} s)"
    )
    return Command(choice.v, choice.w, reason)


class Dodge(ControllerScenario):
    scenario = "dodge"
    priority = PRIORITY
    needs_odometry = True

    tracker: Tracker  # the robot's tracks, scan after scan
    path: PlannedPath | None = None  # the route in force, read with each scan

    def initialise(self) -> None:
        super().initialise()
        self.tracker = Tracker()

    async def data_acquisition(self) -> None:
        # the path in force, from the store's cache (read again on a planned_path note)
        self.path = await self.host.planned_path(self.spec.robot.robot_id) if self.live else None
        await super().data_acquisition()

    def resume(self, lost: Behaviour[Key, ScenarioSpec]) -> None:
        # restarted after an error: the tracks seen so far still hold
        if isinstance(lost, Dodge):
            self.tracker = lost.tracker

    def judge(self, scan: LaserScan, odom: Odometry | None) -> Command | None:
        if odom is None:
            return None
        spec = self.spec
        return decide_for(self.tracker, scan, odom, spec.robot, self.path, spec.params)

    def ttl_s(self) -> float:
        period = self.tracker.period_s
        return min(MAX_TTL_S, max(MIN_TTL_S, TTL_PERIODS * period))

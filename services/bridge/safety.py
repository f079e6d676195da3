"""The safety layer under the decisions: no command drives the robot into what its scan shows.

Whatever priority chose a command2robot row, the bridge checks it against the robot's newest
laser scan before it becomes a cmd_vel, as Nav2's collision monitor sits between controller
and base (its "stop"/"slowdown" polygons, sized from the speed as its "approach" model is).
Pure geometry and bookkeeping here, no I/O; :mod:`.commands` and the reference's bridge
(``pnav/monolith/memory_bridge.py``) both call :meth:`SafetyLayer.judge`.

Speed zones come first: a robot whose centre is inside a speed_limit zone (:mod:`.zones`)
has its linear speed capped at the zone's ``max_speed_mps`` (LIMITED, the reason naming the
zone), and the capped speed is then judged against the scan as any other. The cap holds
whether or not the scan check is enabled: it is people's rule, not a tunable.

The geometry, for a commanded linear speed ``v`` (the angular speed is always kept: turning in
place sweeps nothing new for a round robot, and is how it gets out; a polygon's corners do
sweep, and the sim stops a turn that would push one into something):

- the swept corridor: straight ahead for ``v > 0`` (behind for ``v < 0``), as wide as the
  footprint. For the disc of radius ``R``, a return at (x, y) in the robot's frame (the lidar
  sits at the centre, CONTRACT.md) with ``x`` in the direction of travel and ``|y| < R`` is
  touched after ``|x| - sqrt(R^2 - y^2)`` of travel; for a footprint polygon, after ``|x|``
  less the outline's front (or back) edge at that ``y`` (common/footprint.py,
  ``Footprint.travel_each``): a box's flat front and square corners, not a disc's bulge. A
  polygon commanded to turn as it drives is rolled out along that arc instead
  (common/sweep.py, ``Returns.arc_travel``): its corners swing. The nearest such is the
  free travel ``d``;
- the distance needed: ``|v| * latency + v^2 / (2 * decel) + margin`` (``decel``: the robot
  row's ``max_linear_accel_mps2``, the hardest its model brakes), plus what the robot
  may have travelled since the scan (``age * |last speed sent|``, when that speed was in the
  same direction): the scan is a picture of where the robot was;
- if ``d`` covers it the command passes unchanged; otherwise the speed is reduced to the
  largest one that stops in time (``v_max = a * (sqrt(T^2 + 2 b / a) - T)`` for the budget
  ``b`` left), or to 0 when that is below ``MIN_MPS``.

No fresh scan (none yet, or older than ``scan_max_age_s`` of sim time): the layer has no
evidence either way. By default the command passes (and says so, ``unchecked``), since
stopping would turn a lidar fault, or a robot driven without one (a foreign sim, a test
stand), into a fleet that cannot move; ``blind_mps`` caps the speed instead (0: stop, as
Nav2's collision monitor does when a source times out).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from common import sweep
from common.footprint import Footprint
from common.sweep import (
    MIN_MPS,
    TURN_MARGIN_M,
    Returns,
    arc_reach,
    max_speed,
    stopping_m,
    turn_sweep,
)
from services.bridge.sensor_payloads import LaserScan
from services.bridge.speed_zones import Cap, SpeedZones

FloatArray = npt.NDArray[np.float64]

CLEAR = "clear"
LIMITED = "limited"
STOPPED = "stopped"
UNCHECKED = "unchecked"


@dataclass(frozen=True, slots=True)
class SafetyParams:
    """The layer's tunables (``BridgeSettings`` reads them from ``PNAV_BRIDGE_SAFETY_*``)."""

    enabled: bool = True
    # deceleration the stopping distance assumes; None: each robot's own acceleration limit
    # (robot.max_linear_accel_mps2, from its model), as the sim and a real base brake at it
    decel_mps2: float | None = None
    # how long a command acts before the next one is checked: the decision re-issues at
    # least every 0.1 s of sim time
    latency_s: float = sweep.LATENCY_S
    # distance kept between the footprint and the nearest return once stopped
    margin_m: float = sweep.MARGIN_M
    scan_max_age_s: float = 0.5
    # speed cap with no fresh scan; inf: unchecked, unchanged
    blind_mps: float = math.inf


class Scan:
    """A robot's newest scan as the layer needs it: the returns in the robot's frame.

    The returns are worked out from the record on first use: most scans are superseded by
    the next before a moving command is judged against them.
    """

    __slots__ = ("_record", "_returns", "stamp")

    def __init__(self, record: LaserScan) -> None:
        self.stamp = record.stamp
        self._record = record
        self._returns: Returns | None = None

    @property
    def x(self) -> FloatArray:
        return self.returns.xs

    @property
    def y(self) -> FloatArray:
        return self.returns.ys

    @property
    def returns(self) -> Returns:
        if self._returns is None:
            r = self._record
            self._returns = Returns.of_ranges(
                r.values(), r.angle_min, r.angle_increment, r.range_min
            )
        return self._returns

    def arc_travel(
        self, footprint: Footprint, direction: int, turn_per_m: float, reach_m: float
    ) -> tuple[float, float, float]:
        """common.sweep's :meth:`~common.sweep.Returns.arc_travel` on this scan."""
        return self.returns.arc_travel(footprint, direction, turn_per_m, reach_m)

    def turn_blocked(self, footprint: Footprint, sweep_rad: float) -> tuple[float, float] | None:
        """common.sweep's :meth:`~common.sweep.Returns.turn_blocked` on this scan."""
        return self.returns.turn_blocked(footprint, sweep_rad)

    def free_travel(
        self, direction: int, footprint: Footprint | float
    ) -> tuple[float, float, float]:
        """common.sweep's :meth:`~common.sweep.Returns.free_travel` on this scan."""
        return self.returns.free_travel(direction, footprint)


@dataclass(frozen=True, slots=True)
class Verdict:
    """What the layer made of a command: the linear speed to send, and why."""

    linear: float
    outcome: str  # CLEAR, LIMITED, STOPPED or UNCHECKED
    reason: str = ""
    zone: str | None = None  # the speed zone that capped the speed, if one did
    # the turn rate to send instead of the command's (None: the command's): a footprint
    # polygon whose turn would swing a corner into a return is not turned
    angular: float | None = None

    @property
    def noted(self) -> bool:
        """Whether the row gets the reason written on it (everything but a plain pass)."""
        return self.outcome != CLEAR


class SafetyLayer:
    """Per robot, the newest scan and the last speed sent; judges each command."""

    def __init__(self, params: SafetyParams) -> None:
        self.params = params
        self.scans: dict[str, Scan] = {}
        self.sent: dict[str, float] = {}  # the last linear speed sent, per robot
        # the speed zones and each robot's pose (speed_zones.py): caps applied before the scan's
        self.zones = SpeedZones()

    def scan(self, record: LaserScan) -> None:
        """A valid scan came in: the newest (by stamp) is kept."""
        if not self.params.enabled:
            return
        held = self.scans.get(record.robot_id)
        if held is None or record.stamp >= held.stamp:
            self.scans[record.robot_id] = Scan(record)

    def judge(
        self,
        robot: str,
        linear: float,
        radius: Footprint | float,
        now: float | None,
        decel_mps2: float,
        angular: float = 0.0,
    ) -> Verdict:
        """The verdict on sending ``linear`` (already clamped) to ``robot`` of footprint
        ``radius`` (its polygon, or a disc's radius) that brakes at ``decel_mps2`` (its
        acceleration limit; the params' value instead if set) at sim time ``now`` (None: no
        clock yet, the newest scan counts as fresh); ``angular``, the turn rate going out with
        it, bends a footprint polygon's corridor into the arc it drives. Records the speed the
        verdict sends as the robot's last."""
        decel = self.params.decel_mps2 if self.params.decel_mps2 is not None else decel_mps2
        cap = self.zones.cap(robot)
        if cap is None or abs(linear) <= cap.mps:
            verdict = self._judge(robot, linear, radius, now, decel, angular)
        else:
            verdict = self._capped(robot, linear, cap, radius, now, decel, angular)
        if isinstance(radius, Footprint) and not radius.is_disc and angular != 0.0:
            verdict = self._turn(robot, verdict, radius, now, angular)
        self.sent[robot] = verdict.linear
        return verdict

    def _capped(
        self,
        robot: str,
        linear: float,
        cap: Cap,
        radius: Footprint | float,
        now: float | None,
        decel: float,
        angular: float,
    ) -> Verdict:
        """The verdict on ``linear`` above a speed zone's cap: the cap, then the scan's
        judgement of the capped speed (which may lower it further, or stop)."""
        capped = math.copysign(cap.mps, linear)
        why = f"speed zone '{cap.zone}' caps {cap.mps:g} m/s ({abs(linear):.3f} m/s decided)"
        verdict = self._judge(robot, capped, radius, now, decel, angular)
        if verdict.outcome in (CLEAR, UNCHECKED):
            reason = f"limited to {cap.mps:g} m/s: {why}"
            if verdict.outcome == UNCHECKED:
                reason += f"; {verdict.reason}"
            return Verdict(capped, LIMITED, reason, zone=cap.zone)
        return Verdict(verdict.linear, verdict.outcome, f"{verdict.reason}; {why}", zone=cap.zone)

    def _turn(
        self, robot: str, verdict: Verdict, footprint: Footprint, now: float | None, angular: float
    ) -> Verdict:
        """``verdict`` with the turn taken away when turning ``angular`` for TURN_HORIZON_S
        (the time the command acts, and as long again to stop) would bring a corner of the
        polygon within TURN_MARGIN_M of a return of a fresh scan (both common.sweep's)."""
        p = self.params
        scan = self.scans.get(robot)
        if not p.enabled or scan is None:
            return verdict
        if now is not None and now - scan.stamp > p.scan_max_age_s:
            return verdict
        sweep = turn_sweep(angular, p.latency_s)
        blocked = scan.turn_blocked(footprint, sweep)
        if blocked is None:
            return verdict
        range_m, bearing = blocked
        why = (
            f"turn stopped: turning {math.degrees(sweep):+.0f} deg would bring a corner "
            f"within {TURN_MARGIN_M:.2f} m of the obstacle {range_m:.2f} m away at "
            f"{bearing:+.0f} deg (footprint {_shown(footprint)})"
        )
        outcome = verdict.outcome if verdict.outcome == STOPPED else LIMITED
        reason = f"{verdict.reason}; {why}" if verdict.reason else why
        return Verdict(verdict.linear, outcome, reason, zone=verdict.zone, angular=0.0)

    def sent_stop(self, robot: str) -> None:
        """A stop went out without a verdict (watchdog, shutdown)."""
        self.sent[robot] = 0.0

    def _judge(
        self,
        robot: str,
        linear: float,
        radius: Footprint | float,
        now: float | None,
        decel: float,
        angular: float = 0.0,
    ) -> Verdict:
        p = self.params
        if not p.enabled or linear == 0.0:
            return Verdict(linear, CLEAR)
        scan = self.scans.get(robot)
        age = 0.0 if scan is None or now is None else max(0.0, now - scan.stamp)
        if scan is None or age > p.scan_max_age_s:
            return self._blind(linear, None if scan is None else age)
        direction = 1 if linear > 0 else -1
        last = self.sent.get(robot, 0.0)
        moved = age * abs(last) if last * direction > 0 else 0.0
        # a polygon's arc as far as the stopping distance at this speed could take it, and a
        # little more (common.sweep: what a local controller asks too)
        reach = arc_reach(linear, p.latency_s, decel, p.margin_m) + moved
        travel, range_m, bearing = scan.returns.travel(radius, linear, angular, reach)
        budget = travel - p.margin_m - moved
        speed = abs(linear)
        if budget >= stopping_m(speed, p.latency_s, decel):
            return Verdict(linear, CLEAR)
        allowed = max_speed(budget, p.latency_s, decel)
        way = "ahead" if direction > 0 else "behind"
        why = (
            f"obstacle {range_m:.2f} m {way} at {bearing:+.0f} deg in the scan of "
            f"{age:.2f} s ago leaves {max(budget, 0.0):.3f} m of travel (footprint "
            f"{_shown(radius)}, margin {p.margin_m:.2f} m, {moved:.3f} m moved since); "
            f"{speed:.2f} m/s needs {stopping_m(speed, p.latency_s, decel):.3f} m "
            f"braking at {decel:g} m/s^2"
        )
        if allowed < MIN_MPS:
            return Verdict(0.0, STOPPED, f"stopped: {why}")
        return Verdict(direction * allowed, LIMITED, f"limited to {allowed:.3f} m/s: {why}")

    def _blind(self, linear: float, age: float | None) -> Verdict:
        cap = self.params.blind_mps
        seen = "no scan yet" if age is None else f"newest scan {age:.2f} s old"
        window = f"no scan within {self.params.scan_max_age_s:g} s ({seen})"
        if abs(linear) <= cap:
            return Verdict(linear, UNCHECKED, f"unchecked: {window}")
        if cap < MIN_MPS:
            return Verdict(0.0, STOPPED, f"stopped: {window}, blind speed cap {cap:g} m/s")
        return Verdict(math.copysign(cap, linear), LIMITED, f"limited to {cap:g} m/s: {window}")


def _shown(footprint: Footprint | float) -> str:
    """The footprint as a reason names it."""
    if isinstance(footprint, Footprint):
        if footprint.is_disc:
            return f"{footprint.radius_m:.3f} m"
        return f"polygon, {footprint.circumscribed_m:.3f} m reach"
    return f"{footprint:.3f} m"

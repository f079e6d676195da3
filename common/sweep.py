"""What a footprint sweeps through a scan's returns: the geometry of the bridge's safety layer.

The bridge's safety layer (services/bridge/safety.py) judges each command against these; a
local controller that must not choose what the layer would refuse (pnav_local's dwa with a
footprint polygon) asks the same questions with :func:`passes`, so the two cannot disagree
on a verdict (a controller that keeps choosing a command the layer stops leaves the robot
standing until recovery gives up).

Returns are a scan's hits in the robot's frame (x forward, y left), the lidar at the centre.

- :meth:`Returns.free_travel`: how far the footprint drives straight ahead (or back) before
  its outline meets a return;
- :meth:`Returns.arc_travel`: the same along an arc, a polygon's corners swinging as it turns;
- :meth:`Returns.turn_blocked`: whether turning in place brings a corner up to a return;
- :func:`stopping_m`, :func:`max_speed`: the braking model behind every verdict.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from common.collision import first_contact
from common.footprint import Footprint
from common.scan import beam_angles, readings

FloatArray = npt.NDArray[np.float64]

# The bridge's safety layer's defaults (services/bridge/safety.py, SafetyParams): a local
# controller that asks :func:`passes` uses them unless told otherwise.
MARGIN_M = 0.05
LATENCY_S = 0.1
# Below this a reduced speed is a stop: creeping at 1 cm/s reaches nothing and only wears the
# wheels (the controllers use the same threshold for "not translating").
MIN_MPS = 0.01
# how far past the distance it needs a polygon's arc is rolled out, and the step of it, m
ARC_SLACK_M = 0.1
ARC_STEP_M = 0.02
# a polygon's turn is judged over this long at the commanded rate (at least twice the
# latency: the time it acts, and as long to stop), its corners kept this far from returns
TURN_HORIZON_S = 0.2
TURN_MARGIN_M = 0.01
TURN_STEP_RAD = math.radians(2.0)


def max_speed(budget_m: float, latency_s: float, decel_mps2: float) -> float:
    """The largest speed v with ``v * latency + v^2 / (2 decel) <= budget`` (0 if none)."""
    if not budget_m > 0.0:
        return 0.0
    t, a = latency_s, decel_mps2
    return a * (math.sqrt(t * t + 2.0 * budget_m / a) - t)


def stopping_m(speed: float, latency_s: float, decel_mps2: float) -> float:
    return speed * latency_s + speed * speed / (2.0 * decel_mps2)


def turn_sweep(angular: float, latency_s: float) -> float:
    """The angle a polygon's turn at ``angular`` is judged over (rad)."""
    return angular * max(TURN_HORIZON_S, 2.0 * latency_s)


def arc_reach(linear: float, latency_s: float, decel_mps2: float, margin_m: float) -> float:
    """How much of its arc a polygon driving at ``linear`` is rolled out for: its stopping
    distance, the margin and a little more (what the robot travelled since the scan is
    added by the caller that knows it)."""
    return stopping_m(abs(linear), latency_s, decel_mps2) + margin_m + ARC_SLACK_M


class Returns:
    """A scan's returns in the robot's frame, as the sweeps need them."""

    __slots__ = ("xs", "ys")

    def __init__(self, xs: FloatArray, ys: FloatArray) -> None:
        self.xs, self.ys = xs, ys

    @classmethod
    def of_ranges(
        cls, ranges: FloatArray, angle_min: float, angle_increment: float, range_min: float
    ) -> Returns:
        """A scan's returns: every beam with a finite reading (inf is "nothing in range",
        common.scan.readings says which beams read)."""
        angles = beam_angles(angle_min, angle_increment, len(ranges))
        valid = np.isfinite(ranges) & readings(ranges, range_min)
        r, a = ranges[valid], angles[valid]
        return cls(r * np.cos(a), r * np.sin(a))

    def within(self, reach_m: float) -> Returns:
        """Only the returns within ``reach_m`` of the centre."""
        near = np.hypot(self.xs, self.ys) <= reach_m
        return Returns(self.xs[near], self.ys[near])

    def arc_travel(
        self, footprint: Footprint, direction: int, turn_per_m: float, reach_m: float
    ) -> tuple[float, float, float]:
        """(free travel, range, bearing) of the first return the footprint polygon meets
        driving ahead (``direction`` 1) or back (-1) along the arc that turns ``turn_per_m``
        rad per metre (the turn rate over the speed), for up to ``reach_m`` of it, ARC_STEP_M
        apart; the travel is the last free pose's (inf, inf, 0 if none is met within reach)."""
        xs, ys = self.xs, self.ys
        if not len(xs):
            return math.inf, math.inf, 0.0
        n = max(1, math.ceil(reach_m / ARC_STEP_M))
        s = np.arange(1, n + 1) * (reach_m / n)
        w = turn_per_m
        yaw = w * s
        if abs(w) > 1e-9:
            x, y = direction * np.sin(yaw) / w, direction * (1.0 - np.cos(yaw)) / w
        else:
            x, y = direction * s, np.zeros_like(s)
        poses = np.stack([x, y, yaw], axis=1)
        points = np.stack([xs, ys], axis=1)
        hit = first_contact(footprint, poses, points)
        if hit is None:
            return math.inf, math.inf, 0.0
        travel = float(s[hit - 1]) if hit > 0 else 0.0
        # the return nearest the outline at the pose of contact names it
        c, sn = math.cos(poses[hit, 2]), math.sin(poses[hit, 2])
        dx, dy = xs - poses[hit, 0], ys - poses[hit, 1]
        local = np.stack([c * dx + sn * dy, -sn * dx + c * dy], axis=1)
        i = int(np.argmin(footprint.clearance(local)))
        bearing = math.degrees(math.atan2(float(ys[i]), float(xs[i])))
        return travel, math.hypot(float(xs[i]), float(ys[i])), bearing

    def turn_blocked(self, footprint: Footprint, sweep_rad: float) -> tuple[float, float] | None:
        """(range, bearing) of a return a corner of the polygon would come within
        TURN_MARGIN_M of turning in place by ``sweep_rad``; None if none would."""
        xs, ys = self.xs, self.ys
        if not len(xs):
            return None
        steps = max(1, math.ceil(abs(sweep_rad) / TURN_STEP_RAD))
        yaw = sweep_rad * np.arange(1, steps + 1) / steps
        near = np.hypot(xs, ys) <= footprint.circumscribed_m + TURN_MARGIN_M
        px, py = xs[near], ys[near]
        if not len(px):
            return None
        now = footprint.clearance(np.stack([px, py], axis=1))
        # each near return in the frame of each heading turned through: (steps x n) clearances
        c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
        local = np.stack([c * px + s * py, -s * px + c * py], axis=2).reshape(-1, 2)
        later = footprint.clearance(local).reshape(steps, -1)
        # a corner coming within the margin of a return, and nearer it than now: a return
        # the outline already touches is no reason not to turn away from it
        closing = (later <= TURN_MARGIN_M) & (later < now[None, :] - 1e-6)
        if not closing.any():
            return None
        i = int(np.flatnonzero(closing.any(axis=0))[0])
        return math.hypot(float(px[i]), float(py[i])), math.degrees(math.atan2(py[i], px[i]))

    def free_travel(
        self, direction: int, footprint: Footprint | float
    ) -> tuple[float, float, float]:
        """(free travel, range, bearing) of the nearest return the footprint (a polygon, or
        the disc of a radius) would touch moving straight ahead (``direction`` 1) or back
        (-1), the travel measured from its outline's edge: (inf, inf, 0) if none."""
        xs, ys = self.xs, self.ys
        if isinstance(footprint, Footprint) and not footprint.is_disc:
            travel_each = footprint.travel_each(np.stack([xs, ys], axis=1), direction > 0)
            if not len(travel_each) or not np.isfinite(travel_each).any():
                return math.inf, math.inf, 0.0
            i = int(np.argmin(travel_each))
            bearing = math.degrees(math.atan2(float(ys[i]), float(xs[i])))
            return float(travel_each[i]), math.hypot(float(xs[i]), float(ys[i])), bearing
        radius = footprint.radius_m if isinstance(footprint, Footprint) else footprint
        along = xs * direction
        ahead = (along > 0.0) & (np.abs(ys) < radius)
        if not ahead.any():
            return math.inf, math.inf, 0.0
        index = np.flatnonzero(ahead)
        y = ys[index]
        travel = along[index] - np.sqrt(radius * radius - y * y)
        best = int(np.argmin(travel))
        i = int(index[best])
        bearing = math.degrees(math.atan2(float(ys[i]), float(xs[i])))
        return float(travel[best]), math.hypot(float(xs[i]), float(ys[i])), bearing

    def travel(
        self,
        footprint: Footprint | float,
        linear: float,
        angular: float,
        reach_m: float,
    ) -> tuple[float, float, float]:
        """(free travel, range, bearing) for the motion ``(linear, angular)`` as the safety
        layer measures it: a polygon that turns as it drives along its arc (for ``reach_m``
        of it), anything else straight."""
        direction = 1 if linear > 0 else -1
        if isinstance(footprint, Footprint) and not footprint.is_disc and angular != 0.0:
            return self.arc_travel(footprint, direction, angular / abs(linear), reach_m)
        return self.free_travel(direction, footprint)


def passes(
    returns: Returns,
    footprint: Footprint,
    linear: float,
    angular: float,
    *,
    margin_m: float,
    latency_s: float,
    decel_mps2: float,
) -> bool:
    """Whether the safety layer, judging ``(linear, angular)`` against a scan just taken,
    would send it unchanged: the travel it leaves covers the stopping distance and the
    margin, and a polygon's turn swings no corner up to a return."""
    if linear != 0.0:
        reach = arc_reach(linear, latency_s, decel_mps2, margin_m)
        travel, _, _ = returns.travel(footprint, linear, angular, reach)
        if travel - margin_m < stopping_m(abs(linear), latency_s, decel_mps2):
            return False
    if angular != 0.0 and not footprint.is_disc:
        sweep = turn_sweep(angular, latency_s)
        if returns.turn_blocked(footprint, sweep) is not None:
            return False
    return True

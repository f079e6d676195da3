"""The obstacle-avoidance policy: one laser scan (and the robot's speed) in, advice out.

Pure functions, no I/O, plain Python (360 beams need no numpy). Angles are radians from the
robot's heading, counter-clockwise, as in the ``laser_scan`` table. Three behaviours, named
as the strategies name them, with the priorities CONTRACT.md's conventions give them:

- ``safety_stop`` (100): while the robot translates (|speed| > 1 cm/s), a beam inside the
  corridor its round body sweeps (within ``footprint_radius_m`` of its line of travel, in
  the direction of travel) and closer than footprint + ``safety_margin_m`` + speed x
  ``safety_lookahead_s``: stop, and turn in place so the direction of travel swings toward
  the side with more room. A robot that stands or turns in place sweeps nothing new.
- ``avoid_left`` / ``avoid_right`` (50): an obstacle is a beam closer than
  ``avoid_distance_m`` whose sideways offset from the line of travel is below
  ``avoid_lateral_m`` (walls the robot merely passes do not count), within
  ``avoid_sector_deg`` of the heading. Only on the right: turn left. Only on the left: turn
  right. Dead ahead (within ``avoid_front_deg``) or on both sides: turn toward the half with
  more room (a perfect tie turns left). One decision feeds both names, so they never both
  recommend on one scan; a strategy that enables only one of them gets only that one.

The parameter names and defaults are docs/CONTROLLER.md's, so a strategy row means the same
thing to this controller and to the shipped one.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

logger = logging.getLogger("sql_controller.policy")

AVOID_LEFT, AVOID_RIGHT, SAFETY_STOP = "avoid_left", "avoid_right", "safety_stop"
KNOWN = (AVOID_LEFT, AVOID_RIGHT, SAFETY_STOP)
PRIORITY = {AVOID_LEFT: 50, AVOID_RIGHT: 50, SAFETY_STOP: 100}
VALIDITY_S = 0.5  # CONTRACT.md: a controller recommendation counts for 0.5 s of sim time

MOVING_MPS = 0.01  # slower than this the robot is not translating (odometry noise)
ROOM_TIE_M = 0.02  # two halves whose mean room differs by less are equally free
SAFETY_HORIZON_M = 1.0  # how far "more room" is judged when turning away after a stop
# Ranges are float32 in Postgres: 0.12 m (range_min) reads back as 0.11999999.
RANGE_TOLERANCE_M = 1e-5

Beam = tuple[float, float]  # (range m, inf when nothing or invalid; angle rad in (-pi, pi])


@dataclass(frozen=True)
class Scan:
    id: int
    stamp: float
    angle_min: float
    angle_increment: float
    range_min: float
    ranges: Sequence[float]


@dataclass(frozen=True)
class Robot:
    robot_id: str
    max_linear_mps: float
    max_angular_rps: float
    footprint_radius_m: float


@dataclass(frozen=True)
class Advice:
    """One recommendation to write: which behaviour, the velocity, and why."""

    source: str
    linear: float
    angular: float
    reason: str

    @property
    def priority(self) -> int:
        return PRIORITY[self.source]


_warned: set[tuple[str, str]] = set()


def param(
    params: Mapping[str, Any], key: str, default: float, high: float, low: float = 0.0
) -> float:
    """``params[key]`` if it is a number in [low, high], else the default (warned once): a
    typo in a strategy row must never switch a safety behaviour off."""
    raw = params.get(key)
    if raw is None:
        return default
    if isinstance(raw, int | float) and not isinstance(raw, bool) and low <= raw <= high:
        return float(raw)
    if (key, repr(raw)) not in _warned:
        _warned.add((key, repr(raw)))
        logger.warning(
            "strategy parameter %s=%r is not in [%s, %s]: using %s", key, raw, low, high, default
        )
    return default


def beams(scan: Scan) -> list[Beam]:
    """Every beam as (range, angle); a beam below range_min, NaN or inf is free space."""
    out = []
    for i, value in enumerate(scan.ranges):
        angle = math.remainder(scan.angle_min + i * scan.angle_increment, math.tau)
        if angle == -math.pi:
            angle = math.pi  # the contract's angles are in (-pi, pi]
        valid = math.isfinite(value) and value >= scan.range_min - RANGE_TOLERANCE_M
        out.append((float(value) if valid else math.inf, angle))
    return out


def room(view: Sequence[Beam], low: float, high: float, horizon_m: float) -> float:
    """Mean range of the beams with their angle in [low, high], each capped at horizon_m."""
    ranges = [min(r, horizon_m) for r, a in view if low <= a <= high]
    return sum(ranges) / len(ranges) if ranges else horizon_m


def decide(
    scan: Scan, robot: Robot, speed_mps: float, params: Mapping[str, Any], enabled: Collection[str]
) -> list[Advice]:
    """What the enabled behaviours recommend for this scan (possibly nothing)."""
    view = beams(scan)
    advice: list[Advice] = []
    if SAFETY_STOP in enabled:
        stop = safety_stop(view, robot, speed_mps, params)
        if stop is not None:
            advice.append(stop)
    if AVOID_LEFT in enabled or AVOID_RIGHT in enabled:
        turn = avoid(view, robot, params)
        if turn is not None and turn.source in enabled:
            advice.append(turn)
    return advice


def safety_stop(
    view: Sequence[Beam], robot: Robot, speed_mps: float, params: Mapping[str, Any]
) -> Advice | None:
    if abs(speed_mps) <= MOVING_MPS:
        return None
    margin = param(params, "safety_margin_m", 0.06, high=2.0)
    lookahead = param(params, "safety_lookahead_s", 0.2, high=5.0)
    turn = min(param(params, "safety_turn_rps", 0.8, high=100.0), robot.max_angular_rps)
    way = 1.0 if speed_mps > 0 else -1.0
    body = robot.footprint_radius_m
    # the look-ahead covers what the robot drives before the next scan arrives
    reach = body + margin + abs(speed_mps) * lookahead
    hits = [
        (r, a)
        for r, a in view
        if r <= reach and way * r * math.cos(a) > 0 and abs(r * math.sin(a)) <= body
    ]
    if not hits:
        return None
    r, a = min(hits)
    half = math.pi / 2
    if way > 0:  # a counter-clockwise (positive) turn swings the front to the left
        left = (
            room(view, 0.0, half, SAFETY_HORIZON_M)
            >= room(view, -half, 0.0, SAFETY_HORIZON_M) - ROOM_TIE_M
        )
        angular, toward = (turn, "left") if left else (-turn, "right")
    else:  # ... and the back to the right: swing the back toward the freer back quarter
        back_left = room(view, half, math.pi, SAFETY_HORIZON_M)
        back_right = room(view, -math.pi, -half, SAFETY_HORIZON_M)
        right = back_right >= back_left - ROOM_TIE_M
        angular, toward = (turn, "back-right") if right else (-turn, "back-left")
    going = "forward" if way > 0 else "backward"
    return Advice(
        SAFETY_STOP,
        0.0,
        angular,
        f"driving {going} at {abs(speed_mps):.2f} m/s with an obstacle {r:.2f} m away at "
        f"{math.degrees(a):+.0f} deg in its path (stop distance {reach:.2f} m): stop and turn "
        f"toward the {toward}",
    )


def avoid(view: Sequence[Beam], robot: Robot, params: Mapping[str, Any]) -> Advice | None:
    distance = param(params, "avoid_distance_m", 0.40, high=10.0)
    lateral = param(params, "avoid_lateral_m", 0.25, high=10.0)
    sector_deg = param(params, "avoid_sector_deg", 60.0, low=1.0, high=180.0)
    sector = math.radians(sector_deg)
    front = math.radians(param(params, "avoid_front_deg", 5.0, high=sector_deg))
    near = [
        (r, a)
        for r, a in view
        if r < distance and abs(r * math.sin(a)) < lateral and abs(a) <= sector
    ]
    if not near:
        return None
    ahead = any(abs(a) <= front for _, a in near)
    on_right = any(a < -front for _, a in near)
    on_left = any(a > front for _, a in near)
    if ahead or (on_left and on_right):
        horizon = 2 * distance
        go_left = room(view, 0.0, sector, horizon) >= room(view, -sector, 0.0, horizon) - ROOM_TIE_M
        where = "dead ahead" if ahead else "on both sides"
    else:
        go_left = on_right
        where = "front-right" if on_right else "front-left"
    r, a = min(near)
    stop_distance = param(params, "avoid_stop_distance_m", 0.20, high=10.0)
    speed = (
        0.0
        if r < stop_distance
        else min(param(params, "avoid_linear_mps", 0.05, high=10.0), robot.max_linear_mps)
    )
    rate = min(param(params, "avoid_angular_rps", 1.0, high=100.0), robot.max_angular_rps)
    return Advice(
        AVOID_LEFT if go_left else AVOID_RIGHT,
        speed,
        rate if go_left else -rate,
        f"obstacle {r:.2f} m away at {math.degrees(a):+.0f} deg ({where}), closer than "
        f"{distance:.2f} m and within {lateral:.2f} m of the way: "
        f"{'creep' if speed else 'turn in place'} {'left' if go_left else 'right'}",
    )

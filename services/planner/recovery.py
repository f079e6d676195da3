"""Recovery: what a robot does when it is stuck or makes no progress toward its goal (the
states; the rule that runs them is recovery_rule.py).

One machine per robot and goal, stepped on the robot's odometry (sim time), tested tick by
tick (tests/unit/planner/test_recovery.py):

- ``watch``: the robot is *stuck* when it stayed within ``stuck_radius_m`` of one point for
  ``stuck_s``, and makes *no progress* when its distance to the goal did not shrink by
  ``progress_m`` in ``no_progress_s``. Either starts a recovery, at most ``attempts`` times
  per goal; one more and the goal is given up: ``fail``, with the reason;
- ``back_up``: straight back at ``back_up_mps`` for ``back_up_m``, unless the lidar shows
  something behind (then straight to rotate); a robot whose lidar does not see behind backs
  up only along its own trail, as far as that reaches (``back_turn``: the curvature that
  retraces it, recovery_rule.py and common/trail.py), and rotates where it does not;
- ``rotate``: turn in place by ``rotate_rad`` toward the freer side;
- then ``replan`` (the route is planned again from where the robot is, around what the
  lidar shows now) and back to ``watch``, afresh.

A manoeuvre ends after ``maneuver_s`` whatever happened (a wheel against a wall). A new goal
starts a new machine.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from services.planner.battery_rules import number

WATCH, BACK_UP, ROTATE, FAILED = "watch", "back_up", "rotate", "failed"


@dataclass(frozen=True)
class RecoveryParams:
    stuck_s: float = 5.0
    stuck_radius_m: float = 0.0  # 0: the robot's footprint radius
    no_progress_s: float = 20.0
    progress_m: float = 0.3
    attempts: int = 3
    back_up_m: float = 0.3
    back_up_mps: float = 0.15
    rotate_rad: float = 1.57
    rotate_rps: float = 1.0
    maneuver_s: float = 4.0

    @classmethod
    def read(cls, params: Mapping[str, Any]) -> RecoveryParams:
        """From a strategy's ``recovery_*`` params; absent, not a number or not positive
        (0 allowed for stuck_radius_m): the default."""
        d = cls()
        values: dict[str, Any] = {}
        for name in d.__dataclass_fields__:
            value = number(dict(params), f"recovery_{name}")
            if value is not None and (value > 0 or (name == "stuck_radius_m" and value == 0)):
                values[name] = int(value) if name == "attempts" else value
        return cls(**values)


@dataclass(frozen=True)
class Observation:
    """What one step sees: the robot's pose at ``stamp``, its goal, and, when the machine asks
    (``Machine.wants_scan``), what the lidar says around it."""

    stamp: float
    x: float
    y: float
    yaw: float
    goal: tuple[Any, ...]  # the goal's identity: a new one starts afresh
    goal_x: float
    goal_y: float
    footprint_m: float
    rear_clear: bool = True
    left_freer: bool = True
    # the pose of the goal's route driven to now (a waypoint's seq, None: the goal's own) and
    # how close counts as there: a robot there turns to a heading or stands, never stuck
    leg: int | None = None
    there_m: float = 0.0
    # backing up: the turn per metre of travel (rad/m) that keeps to the trail the robot
    # came along (a lidar blind behind: only that way is known to be clear); None: straight
    # back, the lidar sees there
    back_turn: float | None = None


@dataclass(frozen=True)
class Action:
    """``none``, ``drive`` (a velocity), ``replan`` or ``fail``; ``reason`` for people."""

    kind: str
    linear: float = 0.0
    angular: float = 0.0
    reason: str = ""


NOTHING = Action("none")


def wrap(angle: float) -> float:
    return math.atan2(math.sin(angle), math.cos(angle))


class Machine:
    def __init__(self) -> None:
        self.state = WATCH
        self.goal: tuple[Any, ...] | None = None
        self.leg: int | None = None
        self.attempts = 0
        self.anchor = (0.0, 0.0, 0.0)  # x, y, stamp: where the robot has stayed near since
        self.best = (math.inf, 0.0)  # the nearest it came to the goal, and when
        self.start = (0.0, 0.0, 0.0, 0.0)  # the manoeuvre's x, y, yaw, stamp
        self.turn = 1.0  # the rotation's direction
        self.why = ""

    def _watch_from(self, o: Observation) -> None:
        self.state = WATCH
        self.anchor = (o.x, o.y, o.stamp)
        self.best = (math.hypot(o.goal_x - o.x, o.goal_y - o.y), o.stamp)

    def _begin(self, state: str, o: Observation) -> None:
        self.state = state
        self.start = (o.x, o.y, o.yaw, o.stamp)
        self.turn = 1.0 if o.left_freer else -1.0

    def _moved_on(
        self, o: Observation, p: RecoveryParams
    ) -> tuple[tuple[float, float, float], tuple[float, float]]:
        """The anchors as of ``o``: re-anchored where the robot moved away, the best
        distance to the goal where it came ``progress_m`` nearer."""
        radius = p.stuck_radius_m or o.footprint_m
        anchor, best = self.anchor, self.best
        if math.hypot(o.x - anchor[0], o.y - anchor[1]) > radius:
            anchor = (o.x, o.y, o.stamp)
        distance = math.hypot(o.goal_x - o.x, o.goal_y - o.y)
        if distance < best[0] - p.progress_m:
            best = (distance, o.stamp)
        return anchor, best

    def stuck(self, o: Observation, p: RecoveryParams) -> str | None:
        """Why the robot counts as stuck at ``o`` (None: it does not); changes nothing."""
        (ax, ay, since), best = self._moved_on(o, p)
        radius = p.stuck_radius_m or o.footprint_m
        if o.stamp - since >= p.stuck_s:
            return f"stayed within {radius:.2f} m of ({ax:.2f}, {ay:.2f}) for {p.stuck_s:.1f} s"
        if o.stamp - best[1] >= p.no_progress_s:
            return f"came no {p.progress_m:.2f} m nearer the goal in {p.no_progress_s:.1f} s"
        return None

    def wants_scan(self, o: Observation, p: RecoveryParams) -> bool:
        """Whether this step needs ``rear_clear`` and ``left_freer`` (a manoeuvre is on or
        about to start)."""
        if self.goal != o.goal:
            return False
        return self.state in (BACK_UP, ROTATE) or (
            self.state == WATCH and self.stuck(o, p) is not None
        )

    def step(self, o: Observation, p: RecoveryParams) -> Action:
        if self.goal != o.goal:
            self.goal, self.attempts = o.goal, 0
            self.leg = o.leg
            self._watch_from(o)
        if self.leg != o.leg:  # on to the route's next pose: progress counts toward it
            self.leg = o.leg
            if self.state == WATCH:
                self._watch_from(o)
        if self.state == WATCH and math.hypot(o.goal_x - o.x, o.goal_y - o.y) <= o.there_m:
            self._watch_from(o)  # there: turning to the heading or standing, not stuck
            return NOTHING
        if self.state == WATCH:
            return self._watch(o, p)
        if self.state == BACK_UP:
            return self._back_up(o, p)
        if self.state == ROTATE:
            return self._rotate(o, p)
        return NOTHING  # failed: the goal is given up

    def _watch(self, o: Observation, p: RecoveryParams) -> Action:
        why = self.stuck(o, p)
        self.anchor, self.best = self._moved_on(o, p)
        if why is None:
            return NOTHING
        self.attempts += 1
        self.why = why
        if self.attempts > p.attempts:
            self.state = FAILED
            tries = f"{p.attempts} recover{'y' if p.attempts == 1 else 'ies'}"
            return Action(
                "fail",
                reason=f"no progress: {why}, after {tries} (back up, rotate, re-plan)",
            )
        self._begin(BACK_UP, o)
        return self._back_up(o, p)

    def _label(self, p: RecoveryParams) -> str:
        return f"recovery {self.attempts}/{p.attempts} ({self.why})"

    def _back_up(self, o: Observation, p: RecoveryParams) -> Action:
        sx, sy, _, since = self.start
        gone = math.hypot(o.x - sx, o.y - sy)
        if not o.rear_clear or gone >= p.back_up_m or o.stamp - since >= p.maneuver_s:
            self._begin(ROTATE, o)
            return self._rotate(o, p)
        # backward at -v, a curvature k turns at -v k (the arc's own turn per metre)
        along = "" if o.back_turn is None else " along its trail"
        return Action(
            "drive",
            -p.back_up_mps,
            -p.back_up_mps * (o.back_turn or 0.0),
            f"{self._label(p)}: backing up{along}, {gone:.2f} of {p.back_up_m:.2f} m",
        )

    def _rotate(self, o: Observation, p: RecoveryParams) -> Action:
        _, _, yaw, since = self.start
        turned = abs(wrap(o.yaw - yaw))
        if turned >= min(p.rotate_rad, math.pi - 0.05) or o.stamp - since >= p.maneuver_s:
            label = self._label(p)
            self._watch_from(o)
            return Action("replan", reason=f"{label}: turned {turned:.2f} rad, re-planning")
        side = "left" if self.turn > 0 else "right"
        return Action(
            "drive",
            0.0,
            self.turn * p.rotate_rps,
            f"{self._label(p)}: turning {side}, {turned:.2f} of {p.rotate_rad:.2f} rad",
        )

"""foresight: a controller scenario that predicts, from the last seconds of a robot's rows,
that it will make no progress in the next 3 s, and starts the recovery manoeuvre early.

Per fresh scan it computes the decision's features (pnav_learned.features) and the last
seconds' (pnav_learned.history: progress, displacement, turning, speed, the nearest hit
ahead), and runs a classifier trained on the records (``pnav learn train --target
foresight``) for p, the probability of "no progress within 3 s". When p reaches
``foresight_threshold`` (0.6) while the robot is stalled (it moved less than
``foresight_stall_m``, 0.25 m, in the last second), and both have held for
``foresight_hold_s`` (1.5 s), it backs up (if the lidar sees the rear clear) and turns toward
the freer side, for a second or two, at priority 60: above the local controllers (dwa,
learned_drive: 30) and avoidance (50), below the planner's recovery (70), which still takes
over if the robot does get stuck, and below dodge and the safety band. Then it stays quiet
for ``foresight_cooldown_s`` so that the local controller drives on from the new pose.
Every recommendation's reason names the model, its version, p and the model's confidence.

Why a controller scenario, and not in the planner: the controller runs any number of
scenarios a strategy names, found by entry point (its plug-in group), and its host gives
each one the scan, the odometry at it and the path in force, which are all the features
need; the planner's plug-in group holds one move scenario per strategy, so a predictor
there would need a change to the planner service. The planner's recovery stays as it is:
foresight only acts before it would.

What it remembers of a robot (its history and the manoeuvre under way) is one
:class:`Foresee` in its rule (one rule per robot and scenario, living as long as it).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from common.contract.records import LaserScan, Odometry, Robot
from common.controller_core.params import number
from common.controller_core.scenario import Command
from pnav_learned.features import FloatArray, features, sector_minima
from pnav_learned.history import (
    FORESIGHT_FEATURES,
    HISTORY_FEATURES,
    NEAR_TARGET_M,
    History,
    Sample,
    sample,
)
from pnav_learned.model import Kind
from pnav_learned.registry import Found
from pnav_learned.scenario import LearnedScenario

PRIORITY = 60
PARAMS = "foresight"  # foresight_model, foresight_model_version
TARGET = "no_progress"
KIND = Kind("foresight", FORESIGHT_FEATURES, (TARGET,), "logistic")

WATCH, BACK_UP, TURN = "watch", "back_up", "turn"
REAR_CONE_RAD = math.radians(30)  # beams this close to straight back see the rear
FREER_HORIZON_M = 1.0
REAR_MARGIN_M = 0.1
MOVED_1S = HISTORY_FEATURES.index("moved_1s")


@dataclass(frozen=True)
class Settings:
    """The strategy's ``foresight_*`` params, with the robot's limits applied."""

    threshold: float = 0.6
    min_history_s: float = 1.0
    back_up_s: float = 1.5
    back_up_mps: float = 0.15  # the planner's recovery's defaults
    turn_s: float = 1.5
    turn_rps: float = 1.0
    cooldown_s: float = 5.0
    stall_m: float = 0.25  # a stall: the robot moved less than this in the last second, m
    hold_s: float = 1.5  # act once the fear and a stall have held together this long, s

    @classmethod
    def read(cls, params: Mapping[str, Any], robot: Robot) -> Settings:
        d = cls()
        return cls(
            threshold=number(params, "foresight_threshold", d.threshold, low=0.0, high=1.0),
            min_history_s=number(params, "foresight_min_history_s", d.min_history_s, high=3.0),
            back_up_s=number(params, "foresight_back_up_s", d.back_up_s, high=10.0),
            back_up_mps=min(d.back_up_mps, robot.max_linear_mps),
            turn_s=number(params, "foresight_turn_s", d.turn_s, high=10.0),
            turn_rps=min(d.turn_rps, robot.max_angular_rps),
            cooldown_s=number(params, "foresight_cooldown_s", d.cooldown_s, high=60.0),
            stall_m=number(params, "foresight_stall_m", d.stall_m, high=10.0),
            hold_s=number(params, "foresight_hold_s", d.hold_s, high=10.0),
        )

    @property
    def reach_m(self) -> float:
        return self.back_up_s * self.back_up_mps


def surroundings(scan: LaserScan, radius_m: float, reach_m: float) -> tuple[bool, bool]:
    """(the lidar sees nothing behind within the footprint plus the back-up's reach, the
    left is the freer side). A lidar with no beam behind cannot say the rear is clear."""
    angles = scan.angles()
    ranges = np.asarray(scan.ranges, dtype=np.float64)
    valid = np.isfinite(ranges)
    behind = np.abs(angles) >= math.pi - REAR_CONE_RAD
    near = ranges[behind & valid] <= radius_m + reach_m + REAR_MARGIN_M
    rear_clear = bool(behind.any()) and not bool(near.any())
    capped = np.where(valid, np.minimum(ranges, FREER_HORIZON_M), FREER_HORIZON_M)
    left, right = (angles > 0) & (angles <= math.pi / 2), (angles < 0) & (angles >= -math.pi / 2)
    left_open = float(capped[left].mean()) if left.any() else 0.0
    right_open = float(capped[right].mean()) if right.any() else 0.0
    return rear_clear, left_open >= right_open


class Foresee:
    """One robot's foresight: its history, and the manoeuvre under way (tick by tick:
    tests/unit/learn/test_foresight.py)."""

    def __init__(self) -> None:
        self.history = History()
        self.phase = WATCH
        self.since = -math.inf  # when the phase began (sim s)
        self.quiet_until = -math.inf  # no new manoeuvre before this (sim s)
        self.turn = 1.0
        self.why = ""
        self.p: float | None = None  # the last prediction (tests, people)
        self.feared_since: float | None = None  # since when fear and stall held together

    def predict(self, found: Found, decision: FloatArray) -> tuple[float, float]:
        """(p of no progress within 3 s, the model's confidence) for the newest sample."""
        y, confidence = found.model.outputs(np.concatenate([decision, self.history.features()]))
        return float(y[0]), confidence

    def step(
        self,
        s: Sample,
        decision: FloatArray,
        found: Found,
        surrounding: tuple[bool, bool],
        cfg: Settings,
    ) -> Command | None:
        """Take the newest sample; the manoeuvre's command for it, or None."""
        self.history.add(s)
        if self.phase != WATCH:
            return self._manoeuvre(s.stamp, surrounding[0], cfg)
        self.feared_since, since = None, self.feared_since
        if s.stamp < self.quiet_until or s.target_dist < NEAR_TARGET_M:
            return None
        history = self.history.features()
        if history[0] < cfg.min_history_s:
            return None  # too little of the last seconds to judge them
        p, confidence = self.predict(found, decision)
        self.p = p
        moved = float(history[MOVED_1S])
        if p < cfg.threshold or moved >= cfg.stall_m:
            return None  # no fear, or a fear the robot's own motion does not bear out
        # a fear borne out by a stall acts only once both have held hold_s: dwa slows and
        # turns in place at bends for a second or so, and a stale model fears those too
        self.feared_since = s.stamp if since is None else since
        if s.stamp - self.feared_since < cfg.hold_s - 1e-9:
            return None
        self.why = (
            f"foresight: {found.label}: no progress within 3 s predicted, p {p:.2f} >="
            f" {cfg.threshold:.2f}, confidence {confidence:.2f}, with the robot stalled"
            f" (under {cfg.stall_m:.2f} m a second) for {s.stamp - self.feared_since:.1f} s"
        )
        self.feared_since = None
        self.turn = 1.0 if surrounding[1] else -1.0
        self.phase, self.since = BACK_UP if surrounding[0] else TURN, s.stamp
        return self._manoeuvre(s.stamp, surrounding[0], cfg)

    def _manoeuvre(self, now: float, rear_clear: bool, cfg: Settings) -> Command | None:
        if self.phase == BACK_UP:
            if rear_clear and now - self.since < cfg.back_up_s:
                return Command(-cfg.back_up_mps, 0.0, f"{self.why}: backing up")
            self.phase, self.since = TURN, now
        if now - self.since < cfg.turn_s:
            side = "left" if self.turn > 0 else "right"
            return Command(0.0, self.turn * cfg.turn_rps, f"{self.why}: turning {side}")
        self.phase, self.quiet_until = WATCH, now + cfg.cooldown_s
        return None


class Foresight(LearnedScenario):
    scenario = "foresight"
    priority = PRIORITY
    params = PARAMS
    kind = KIND

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        # this robot's foresight: the one place its state lives between scans
        self.memory = Foresee()

    def judge(self, scan: LaserScan, odom: Odometry | None) -> Command | None:
        found = self.model()
        path = self.path
        if found is None or path is None or path.empty or odom is None:
            return None
        robot, pose = self.spec.robot, (odom.x, odom.y, odom.yaw)
        sectors = sector_minima(scan.ranges, scan.angle_min, scan.angle_increment)
        x = features(sectors, (odom.linear_mps, odom.angular_rps), pose, path.xs, path.ys)
        end = (float(path.xs[-1]), float(path.ys[-1]))
        cfg = Settings.read(self.spec.params, robot)
        around = surroundings(scan, robot.footprint_radius_m, cfg.reach_m)
        now = sample(odom.stamp, pose, odom.linear_mps, end, x)
        command = self.memory.step(now, x, found, around, cfg)
        if command is None:
            return None
        model = found.model
        inputs = {
            "planned_path": path.id,
            "model": model.name,
            "model_version": model.version,
            "p_no_progress": round(self.memory.p or 0.0, 3),
        }
        return Command(command.linear, command.angular, command.reason, inputs)

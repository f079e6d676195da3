"""learned_drive: a controller scenario that drives with a model trained on the stack's own
decisions (``pnav learn train``), e.g. a policy distilled from dwa's.

Per fresh scan it computes the decision's features (pnav_learned.features: scan sectors,
odometry, the planned path's carrot and target in the robot's frame), runs the model named
by the strategy's params and recommends the velocity it predicts, clamped to the robot's
limits, at priority 30 (dwa's: a local controller; avoid, recovery and the safety band keep
the last word, and the bridge's safety layer judges the command as any other). Its reason
names the model, its version and its confidence.

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

from typing import Any

import numpy as np

from common.contract.planned_path import PlannedPath
from common.contract.records import LaserScan, Odometry, Robot
from common.controller_core.scenario import Command
from pnav_learned.features import features, sector_minima
from pnav_learned.model import DRIVE, Model
from pnav_learned.scenario import LearnedScenario

PRIORITY = 30
PARAMS = "learned"  # learned_model, learned_model_version


def recommend(
    model: Model,
    scan: LaserScan,
    odom: Odometry,
    robot: Robot,
    path: PlannedPath,
    label: str | None = None,
) -> Command:
    sectors = sector_minima(scan.ranges, scan.angle_min, scan.angle_increment)
    x = features(
        sectors,
        (odom.linear_mps, odom.angular_rps),
        (odom.x, odom.y, odom.yaw),
        path.xs,
        path.ys,
    )
    linear, angular, confidence = model.predict(x)
    linear = float(np.clip(linear, -robot.max_linear_mps, robot.max_linear_mps))
    angular = float(np.clip(angular, -robot.max_angular_rps, robot.max_angular_rps))
    label = label or f"model {model.name} version {model.version}"
    return Command(
        linear,
        angular,
        f"learned_drive: {label}, confidence"
        f" {confidence:.2f} (share of features within the training data's range)",
        {"planned_path": path.id, "model": model.name, "model_version": model.version},
    )


class LearnedDrive(LearnedScenario):
    scenario = "learned_drive"
    priority = PRIORITY
    params = PARAMS
    kind = DRIVE

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
        return recommend(found.model, scan, odom, self.spec.robot, path, found.label)

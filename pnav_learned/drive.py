"""learned_drive: a controller scenario that drives with a model trained on the stack's own
decisions (``pnav learn train``), e.g. a policy distilled from dwa's.

Per fresh scan it computes the decision's features (pnav_learned.features: scan sectors,
odometry, the planned path's carrot and target in the robot's frame), runs the model named
by the strategy's params and recommends the velocity it predicts, clamped to the robot's
limits, at priority 30 (dwa's: a local controller; avoid, recovery and the safety band keep
the last word, and the bridge's safety layer judges the command as any other). Its reason
names the model, its version and its confidence.

Params: ``learned_model`` (the model file; a relative path is taken from the directory
``PNAV_MODEL_DIR`` names, else the controller's working directory) and, optionally,
``learned_model_version`` (the version the file must have). A model file that is missing,
corrupt, made for other features or of another version is refused when loaded, logged once
with the reason, and the scenario stands down (recommends nothing) until the params or the
file change: the other scenarios of the strategy go on.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from common import log
from common.contract.planned_path import PlannedPath
from common.contract.records import LaserScan, Odometry, Robot
from common.controller_core.scenario import Command, ControllerScenario
from pnav_learned.errors import ModelRefused
from pnav_learned.features import features, sector_minima
from pnav_learned.model import Model, load

PRIORITY = 30
MODEL_PARAM = "learned_model"
VERSION_PARAM = "learned_model_version"

logger = logging.getLogger("pnav.controller")

# (path, version, file's mtime) -> the model or why it was refused; shared by the robots
_cache: dict[tuple[str, str | None, float], Model | str] = {}


def model_path(name: str) -> Path:
    p = Path(name)
    return p if p.is_absolute() else Path(os.environ.get("PNAV_MODEL_DIR", ".")) / p


def model_for(params: Mapping[str, Any]) -> Model | str:
    """The model the params name, or why there is none (cached until the file changes)."""
    name, version = params.get(MODEL_PARAM), params.get(VERSION_PARAM)
    if not isinstance(name, str) or not name:
        return f"no model: the strategy's params name none ({MODEL_PARAM})"
    wanted = version if isinstance(version, str) else None
    path = model_path(name)
    try:
        mtime = path.stat().st_mtime
    except OSError:
        mtime = -1.0
    key = (str(path), wanted, mtime)
    if key not in _cache:
        try:
            _cache[key] = load(path, wanted)
        except ModelRefused as exc:
            _cache[key] = f"model refused: {exc}"
        found = _cache[key]
        log.event(
            logger,
            logging.WARNING if isinstance(found, str) else logging.INFO,
            "learned_drive model",
            path=str(path),
            outcome=found if isinstance(found, str) else f"loaded version {found.version}",
        )
    return _cache[key]


def recommend(
    model: Model, scan: LaserScan, odom: Odometry, robot: Robot, path: PlannedPath
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
    return Command(
        linear,
        angular,
        f"learned_drive: model {model.name} version {model.version}, confidence"
        f" {confidence:.2f} (share of features within the training data's range)",
        {"planned_path": path.id, "model": model.name, "model_version": model.version},
    )


class LearnedDrive(ControllerScenario):
    scenario = "learned_drive"
    priority = PRIORITY
    needs_odometry = True

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.path: PlannedPath | None = None
        self.stopped_for: int | None = None
        self.refusal: str | None = None  # why this scenario stands down, for tests and people

    async def data_acquisition(self) -> None:
        self.path = await self.host.planned_path(self.spec.robot.robot_id) if self.live else None
        await super().data_acquisition()

    @classmethod
    def decide(
        cls, scan: LaserScan, odom: Odometry | None, robot: Robot, params: Mapping[str, Any]
    ) -> Command | None:
        return None  # the path is read in acquisition: ``judge`` decides

    def judge(self, scan: LaserScan, odom: Odometry | None) -> Command | None:
        found = model_for(self.spec.params)
        if isinstance(found, str):
            self.refusal = found
            return None  # stand down: the strategy's other scenarios drive
        self.refusal = None
        path = self.path
        if path is None or odom is None:
            return None
        if path.empty:
            if self.stopped_for == path.id:
                return None
            self.stopped_for = path.id
            return Command(0.0, 0.0, f"learned_drive: no path ({path.target}): stop")
        return recommend(found, scan, odom, self.spec.robot, path)

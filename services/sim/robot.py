"""A robot in the sim: a differential drive of some robot model, moved kinematically.

The model (common/robotmodel.py, ``models/*.yaml``) gives the body, the limits and the lidar.
The sim integrates the commanded unicycle velocities (v, w) each physics step and places the
body there, instead of simulating wheel torques and friction: the motion is then exactly
reproducible for a given command sequence, which benchmarks and tests rely on. The motors
reach a command no faster than the model's acceleration limits allow (:func:`accelerate`),
as a diff-drive controller with acceleration limits does. The wheel geometry is kept to
report wheel speeds and to publish the robot's limits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from common.robotmodel import DEFAULT_MODEL, RobotModel, load_model

# the default robot, loaded from models/ like any other: no model figure lives in code
BURGER = load_model(DEFAULT_MODEL)


def clamp_command(model: RobotModel, linear: float, angular: float) -> tuple[float, float]:
    """Clamp a command to the robot's limits, as the motor controller would."""
    v = max(-model.max_linear_mps, min(model.max_linear_mps, linear))
    w = max(-model.max_angular_rps, min(model.max_angular_rps, angular))
    return v, w


def accelerate(current: float, target: float, limit: float, dt: float) -> float:
    """The velocity one step of ``dt`` later, moving from ``current`` toward ``target`` by at
    most ``limit * dt`` (speeding up and slowing down alike)."""
    step = limit * dt
    if target > current + step:
        return current + step
    if target < current - step:
        return current - step
    return target


def wheel_speeds(model: RobotModel, linear: float, angular: float) -> tuple[float, float]:
    """(left, right) wheel angular speeds, rad/s, for a unicycle command."""
    half = model.wheel_separation_m / 2.0
    left = (linear - angular * half) / model.wheel_radius_m
    right = (linear + angular * half) / model.wheel_radius_m
    return left, right


def normalize_angle(angle: float) -> float:
    """The contract's angle range, (-pi, pi]."""
    a = math.fmod(angle, 2.0 * math.pi)
    if a <= -math.pi:
        a += 2.0 * math.pi
    elif a > math.pi:
        a -= 2.0 * math.pi
    return a


def integrate(
    x: float, y: float, yaw: float, linear: float, angular: float, dt: float
) -> tuple[float, float, float]:
    """Exact unicycle motion over ``dt`` at constant (linear, angular): an arc, or a line.

    Positive angular is counter-clockwise, so yaw increases. The arc's chord, of length
    ``linear * dt * sin(h) / h`` at heading ``yaw + h`` (h = half the turn), is exact and, unlike
    the radius form ``linear / angular``, loses no precision as the turn rate goes to 0.
    """
    h = angular * dt / 2.0
    chord = linear * dt * (math.sin(h) / h if h != 0.0 else 1.0)
    mid = yaw + h
    return x + chord * math.cos(mid), y + chord * math.sin(mid), normalize_angle(yaw + 2.0 * h)


@dataclass
class RobotState:
    """One robot's pose, the command it obeys and the velocities it really achieved."""

    robot_id: str
    x: float
    y: float
    yaw: float
    model: RobotModel = BURGER
    cmd_linear: float = 0.0
    cmd_angular: float = 0.0
    # what the motors run at: the command reached at the acceleration limits
    drive_linear: float = 0.0
    drive_angular: float = 0.0
    linear: float = 0.0  # achieved this step (0 when blocked by an obstacle)
    angular: float = 0.0

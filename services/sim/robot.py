"""The robot model: a TurtleBot3 Burger-class differential drive, moved kinematically.

The sim integrates the commanded unicycle velocities (v, w) each physics step and places the
body there, instead of simulating wheel torques and friction: the motion is then exactly
reproducible for a given command sequence, which benchmarks and tests rely on. The wheel
geometry is kept to report wheel speeds and to publish the robot's limits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class DiffDriveParams:
    """Physical limits of one robot model; the field names end in the contract's units."""

    model: str = "turtlebot3_burger"
    wheel_radius_m: float = 0.033
    wheel_separation_m: float = 0.160
    max_linear_mps: float = 0.22
    max_angular_rps: float = 2.84
    footprint_radius_m: float = 0.105
    height_m: float = 0.192
    # the LDS-01 sits on top of the Burger, about 0.17 m above the floor
    lidar_height_m: float = 0.17
    battery_capacity_wh: float = 19.98

    def limits(self) -> dict[str, float | str]:
        """The `robot` table's limit columns, as the world message carries them."""
        return {
            "model": self.model,
            "wheel_radius_m": self.wheel_radius_m,
            "wheel_separation_m": self.wheel_separation_m,
            "max_linear_mps": self.max_linear_mps,
            "max_angular_rps": self.max_angular_rps,
            "footprint_radius_m": self.footprint_radius_m,
            "battery_capacity_wh": self.battery_capacity_wh,
        }


BURGER = DiffDriveParams()


def clamp_command(params: DiffDriveParams, linear: float, angular: float) -> tuple[float, float]:
    """Clamp a command to the robot's limits, as the motor controller would."""
    v = max(-params.max_linear_mps, min(params.max_linear_mps, linear))
    w = max(-params.max_angular_rps, min(params.max_angular_rps, angular))
    return v, w


def wheel_speeds(params: DiffDriveParams, linear: float, angular: float) -> tuple[float, float]:
    """(left, right) wheel angular speeds, rad/s, for a unicycle command."""
    half = params.wheel_separation_m / 2.0
    left = (linear - angular * half) / params.wheel_radius_m
    right = (linear + angular * half) / params.wheel_radius_m
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
    params: DiffDriveParams = BURGER
    cmd_linear: float = 0.0
    cmd_angular: float = 0.0
    linear: float = 0.0  # achieved this step (0 when blocked by an obstacle)
    angular: float = 0.0

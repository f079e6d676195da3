"""The battery: an energy store that drains with motion and charges at a station.

Model (documented in docs/SIM.md), per physics step of ``dt`` seconds:

    load_w   = idle_w + k_linear * |v| + k_angular * |w|
    net_w    = load_w - charge_w          (charge_w: the station's power while inside it)
    energy  -= net_w * dt / 3600          (Wh), then clamped to [0, capacity]

The defaults suit a TurtleBot3 Burger: a Raspberry Pi, the OpenCR board and the LDS-01 lidar
draw about 1.5 W at rest; two Dynamixel XL430 motors add about 2.2 W at 0.22 m/s
(k_linear 10 W per m/s) and about 1.4 W turning at 2.84 rad/s (k_angular 0.5 W per rad/s).
A full 19.98 Wh battery then lasts about 13 h idle and about 4 h driving and turning flat
out (5.12 W).
"""

from __future__ import annotations

from dataclasses import dataclass

from common.robotmodel import DEFAULT_MODEL, load_model

# the default capacity; the sim gives each robot its own model's (robot.battery_capacity_wh)
_DEFAULT_CAPACITY_WH = load_model(DEFAULT_MODEL).battery_capacity_wh


@dataclass(frozen=True)
class BatteryModel:
    capacity_wh: float = _DEFAULT_CAPACITY_WH
    idle_w: float = 1.5
    k_linear_w_per_mps: float = 10.0
    k_angular_w_per_rps: float = 0.5

    def load_w(self, linear: float, angular: float) -> float:
        return (
            self.idle_w
            + self.k_linear_w_per_mps * abs(linear)
            + (self.k_angular_w_per_rps * abs(angular))
        )


@dataclass
class Battery:
    model: BatteryModel
    energy_wh: float
    power_w: float = 0.0  # net power drawn in the last step, W; negative while charging
    charging: bool = False

    @classmethod
    def at_percent(cls, model: BatteryModel, percent: float) -> Battery:
        percent = max(0.0, min(100.0, percent))
        return cls(model=model, energy_wh=model.capacity_wh * percent / 100.0)

    @property
    def capacity_wh(self) -> float:
        return self.model.capacity_wh

    @property
    def percentage(self) -> float:
        return 100.0 * self.energy_wh / self.model.capacity_wh

    @property
    def empty(self) -> bool:
        return self.energy_wh <= 0.0

    def step(self, dt: float, linear: float, angular: float, charge_w: float | None) -> None:
        """Advance ``dt`` seconds at the achieved velocities; ``charge_w`` is the power of the
        station the robot is in, None when it is in none."""
        self.charging = charge_w is not None
        load = self.model.load_w(linear, angular)
        net = load - (charge_w or 0.0)
        energy = self.energy_wh - net * dt / 3600.0
        if energy >= self.model.capacity_wh:
            energy = self.model.capacity_wh
            # full: the charger carries the load and nothing flows into the battery
            if net < 0.0:
                net = 0.0
        if energy <= 0.0:
            energy = 0.0
            # flat: the robot is dead, nothing is drawn (and the motors do not move)
            if net > 0.0:
                net = 0.0
        self.energy_wh = energy
        self.power_w = net

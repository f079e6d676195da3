"""The dwa scenario's parameters (``strategy.params``), with defaults (docs/CONTROLLER.md,
"dwa").

A missing key takes its default; a value that is not a number in range is logged once and
takes its default (services.controller.params.number), so a typo never stops the robot's
local controller. The speeds, accelerations and footprint are the robot row's, never here.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from pnav_local.trajectories import Weights
from services.controller.params import number


@dataclass(frozen=True)
class DwaParams:
    horizon_s: float = 1.2  # how far ahead each trajectory is rolled out
    steps: int = 10  # poses per trajectory
    linear_samples: int = 9
    angular_samples: int = 17
    window_s: float = 0.3  # the acceleration window: until the next decision takes effect
    delay_s: float = 0.1  # scan to wheels: the robot keeps its velocity meanwhile
    margin_m: float = 0.05  # kept beyond the footprint radius
    lookahead_m: float = 0.0  # the carrot along the path; 0: beyond what the horizon reaches
    # a slow arc must stay clear as far as the robot goes in this long at top speed, not
    # only for the horizon (the Jackal: 0.4 m; the Burger: 4 cm, nearly the horizon alone)
    min_travel_s: float = 0.2
    clearance_cap_m: float = 0.5  # gaps beyond this score no better
    blocked_path_factor: float = 0.2  # the path weight while the path runs into a hit
    obstacle_range_m: float = 0.0  # hits farther than this are ignored; 0: what the horizon reaches
    # safety_stop's reach (its own params): the speed is kept below what would trigger it
    safety_margin_m: float = 0.06
    safety_lookahead_s: float = 0.2
    weights: Weights = field(default_factory=Weights)

    @classmethod
    def read(cls, params: Mapping[str, Any]) -> DwaParams:
        d, w = cls(), Weights()

        def get(key: str, default: float, low: float = 0.0, high: float = 1e3) -> float:
            return number(params, key, default, low=low, high=high)

        return cls(
            horizon_s=get("dwa_horizon_s", d.horizon_s, 0.2, 10.0),
            steps=int(get("dwa_steps", d.steps, 2, 50)),
            linear_samples=int(get("dwa_linear_samples", d.linear_samples, 1, 50)),
            angular_samples=int(get("dwa_angular_samples", d.angular_samples, 1, 100)),
            window_s=get("dwa_window_s", d.window_s, 0.01, 5.0),
            delay_s=get("dwa_delay_s", d.delay_s, 0.0, 2.0),
            margin_m=get("dwa_margin_m", d.margin_m, 0.0, 2.0),
            lookahead_m=get("dwa_lookahead_m", d.lookahead_m, 0.0, 20.0),
            min_travel_s=get("dwa_min_travel_s", d.min_travel_s, 0.0, 10.0),
            clearance_cap_m=get("dwa_clearance_cap_m", d.clearance_cap_m, 0.01, 10.0),
            blocked_path_factor=get("dwa_blocked_path_factor", d.blocked_path_factor, 0.0, 1.0),
            obstacle_range_m=get("dwa_obstacle_range_m", d.obstacle_range_m, 0.0, 100.0),
            safety_margin_m=get("safety_margin_m", d.safety_margin_m, 0.0, 2.0),
            safety_lookahead_s=get("safety_lookahead_s", d.safety_lookahead_s, 0.0, 5.0),
            weights=Weights(
                progress=get("dwa_progress_weight", w.progress),
                path=get("dwa_path_weight", w.path),
                heading=get("dwa_heading_weight", w.heading),
                clearance=get("dwa_clearance_weight", w.clearance),
                speed=get("dwa_speed_weight", w.speed),
            ),
        )

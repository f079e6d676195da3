"""The dwa scenario's parameters (``strategy.params``), with defaults (docs/CONTROLLER.md,
"dwa").

A missing key takes its default; a value that is not a number in range is logged once and
takes its default (common.controller_core.params.number), so a typo never stops the robot's
local controller. The speeds, accelerations and footprint are the robot row's, never here.

A strategy row is people's, and each size within its range still multiplies the others:
50 linear x 100 angular samples x 50 steps rolled out 255,000 poses, 0.5 to 2.4 s and a
gigabyte per decision, while every other rule of the controller waited. So the window's
grid and the steps are fitted to :data:`POSE_BUDGET` together (:func:`fit_budget`): the
shape asked, scaled down, logged once and named in every recommendation's reason.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from common import log
from common.controller_core.params import number
from pnav_local.trajectories import Weights

logger = logging.getLogger("pnav.controller")

# The most poses one decision rolls out: trajectories (linear x (angular + 2) samples: the
# window adds w = 0 and the turn rate facing the carrot) x steps. The defaults use 1,710
# (9 x 19 x 10); 6,000 keeps a decision within a few milliseconds (docs/BENCHMARKS.md).
POSE_BUDGET = 6000
MIN_STEPS = 2
_DEFAULT_GRID = (9, 17, 10)  # linear, angular samples, steps: what the budget scales from

_warned: set[tuple[int, int, int]] = set()


def poses(linear: int, angular: int, steps: int) -> int:
    """The most poses a window of ``linear`` x ``angular`` samples rolls out in ``steps``."""
    return linear * (angular + 2) * steps


def fit_budget(linear: int, angular: int, steps: int) -> tuple[int, int, int]:
    """(linear, angular, steps) within :data:`POSE_BUDGET`: as asked when they fit, else
    scaled down toward the defaults' proportions, one at a time the one farthest above its
    default (so 50 x 100 x 50 becomes 14 x 26 x 15, each about 1.5 x its default)."""
    grid = [linear, angular, steps]
    lowest = (1, 1, MIN_STEPS)
    while poses(*grid) > POSE_BUDGET:
        at = zip(grid, _DEFAULT_GRID, lowest, strict=True)
        shares = [g / d if g > low else 0.0 for g, d, low in at]
        grid[shares.index(max(shares))] -= 1
    return grid[0], grid[1], grid[2]


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
    # the robot faces the carrot only while the line to it passes this near the path's
    # bends; else where the path bends out of that sight (trajectories.sighted); 0: always
    # the carrot
    sight_m: float = 0.1
    # a slow arc must stay clear as far as the robot goes in this long at top speed, not
    # only for the horizon (the Jackal: 0.4 m; the Burger: 4 cm, nearly the horizon alone)
    min_travel_s: float = 0.2
    clearance_cap_m: float = 0.5  # gaps beyond this score no better
    # a footprint polygon's two-segment roll-outs (trajectories.with_bends): straight on for
    # bend_s, then one of bend_turns turn rates (and the one facing the path's lead); 0: none
    bend_s: float = 0.4
    bend_turns: int = 8
    # 1: the straight-then-turn roll-outs everywhere; 0: only where the box could not turn in
    # place at the bend (dwa.bends_needed). Where things move, a bend's later turn is judged
    # by nobody (dwa takes the scan as still, dodge judges the motion being made): GOTO_DODGE
    # sets 0
    bends_in_open: bool = True
    # a footprint polygon that can move nowhere with margin_m is admitted with this (0: never)
    squeeze_margin_m: float = 0.02
    blocked_path_factor: float = 0.2  # the path weight while the path runs into a hit
    obstacle_range_m: float = 0.0  # hits farther than this are ignored; 0: what the horizon reaches
    # safety_stop's reach (its own params): the speed is kept below what would trigger it
    safety_margin_m: float = 0.06
    safety_lookahead_s: float = 0.2
    weights: Weights = field(default_factory=Weights)
    # (linear, angular, steps) the strategy asked for when over POSE_BUDGET (None: as asked)
    asked: tuple[int, int, int] | None = None

    @property
    def scaled(self) -> str:
        """For the recommendation's reason: how the grid was fitted to the budget, if it was."""
        if self.asked is None:
            return ""
        grid = f"{self.linear_samples} x {self.angular_samples} samples x {self.steps} steps"
        asked = " x ".join(str(n) for n in self.asked)
        return f"; params scaled to {grid} (asked {asked}: over the {POSE_BUDGET}-pose budget)"

    @classmethod
    def read(cls, params: Mapping[str, Any]) -> DwaParams:
        d, w = cls(), Weights()

        def get(key: str, default: float, low: float = 0.0, high: float = 1e3) -> float:
            return number(params, key, default, low=low, high=high)

        asked = (
            int(get("dwa_linear_samples", d.linear_samples, 1, 50)),
            int(get("dwa_angular_samples", d.angular_samples, 1, 100)),
            int(get("dwa_steps", d.steps, MIN_STEPS, 50)),
        )
        linear, angular, steps = fit_budget(*asked)
        if (linear, angular, steps) != asked:
            _warn_scaled(asked, (linear, angular, steps))
        return cls(
            horizon_s=get("dwa_horizon_s", d.horizon_s, 0.2, 10.0),
            steps=steps,
            linear_samples=linear,
            angular_samples=angular,
            window_s=get("dwa_window_s", d.window_s, 0.01, 5.0),
            delay_s=get("dwa_delay_s", d.delay_s, 0.0, 2.0),
            margin_m=get("dwa_margin_m", d.margin_m, 0.0, 2.0),
            lookahead_m=get("dwa_lookahead_m", d.lookahead_m, 0.0, 20.0),
            sight_m=get("dwa_sight_m", d.sight_m, 0.0, 20.0),
            min_travel_s=get("dwa_min_travel_s", d.min_travel_s, 0.0, 10.0),
            clearance_cap_m=get("dwa_clearance_cap_m", d.clearance_cap_m, 0.01, 10.0),
            bend_s=get("dwa_bend_s", d.bend_s, 0.0, 10.0),
            bend_turns=int(get("dwa_bend_turns", d.bend_turns, 0, 16)),
            bends_in_open=get("dwa_bends_in_open", float(d.bends_in_open), 0.0, 1.0) >= 0.5,
            squeeze_margin_m=get("dwa_squeeze_margin_m", d.squeeze_margin_m, 0.0, 2.0),
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
            asked=None if (linear, angular, steps) == asked else asked,
        )


def _warn_scaled(asked: tuple[int, int, int], used: tuple[int, int, int]) -> None:
    """Log once per grid asked that it was scaled to the budget (a row read on every scan)."""
    if asked in _warned:
        return
    _warned.add(asked)
    log.event(
        logger,
        logging.WARNING,
        "dwa params over the work budget; scaled down",
        asked="dwa_linear_samples={} dwa_angular_samples={} dwa_steps={}".format(*asked),
        used="dwa_linear_samples={} dwa_angular_samples={} dwa_steps={}".format(*used),
        poses_asked=poses(*asked),
        budget=POSE_BUDGET,
    )

"""The bridge's own tunables, with the defaults docs/BRIDGE.md gives.

The connections (Postgres, Zenoh) come from :class:`common.config.ServiceConfig`; these are
the few knobs specific to the bridge, read from optional ``PNAV_BRIDGE_*`` variables:

==============================  =============================================  =======
variable                        meaning                                        default
==============================  =============================================  =======
PNAV_BRIDGE_WATCHDOG_S          sim seconds without a fresh command before     0.5
                                the robot is sent a zero velocity
PNAV_BRIDGE_COMMAND_PERIOD_MS   wall period of the command2robot re-read that  50
                                covers lost notifications
PNAV_BRIDGE_PRUNE_PERIOD_S      wall period of ``prune_sensor_rows()``         5
PNAV_BRIDGE_STATS_PERIOD_S      wall period of the counters log line           10
PNAV_BRIDGE_SAFETY              the safety layer under the decisions (on/off)  on
PNAV_BRIDGE_SAFETY_DECEL_MPS2   deceleration the stopping distance assumes     (each
                                (empty: each robot's acceleration limit)       robot's)
PNAV_BRIDGE_SAFETY_LATENCY_S    sim seconds a command acts before the next     0.1
PNAV_BRIDGE_SAFETY_MARGIN_M     gap kept between footprint and obstacle, m     0.05
PNAV_BRIDGE_SAFETY_SCAN_AGE_S   sim age beyond which a scan is not evidence    0.5
PNAV_BRIDGE_SAFETY_BLIND_MPS    speed cap with no fresh scan (empty: none)     (none)
PNAV_BRIDGE_TRACE               on the ROS 2 link, a latency trace of each     (none)
                                command sent (common/trace.py)
==============================  =============================================  =======

The safety layer (:mod:`services.bridge.safety`, docs/BRIDGE.md "Safety layer") checks every
command against the robot's newest scan before it goes out.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field

from common.config import env_number
from common.errors import ConfigError
from services.bridge.safety import SafetyParams


def _optional_positive(env: Mapping[str, str], name: str) -> float | None:
    return _positive(env, name, math.nan) if env.get(name, "").strip() else None


def _positive(env: Mapping[str, str], name: str, default: float, scale: float = 1.0) -> float:
    return env_number(
        env,
        name,
        default,
        lambda raw: float(raw) * scale,
        ok=lambda value: value > 0,  # also refuses NaN
        must="must be positive",
    )


def _non_negative(env: Mapping[str, str], name: str, default: float) -> float:
    return env_number(
        env,
        name,
        default,
        float,
        ok=lambda value: 0 <= value < math.inf,  # also refuses NaN
        must="must be a finite number >= 0",
    )


def _switch(env: Mapping[str, str], name: str, default: bool) -> bool:
    raw = env.get(name, "").strip().lower()
    if not raw:
        return default
    if raw in ("1", "true", "yes", "on"):
        return True
    if raw in ("0", "false", "no", "off"):
        return False
    raise ConfigError(f"{name}={raw!r} is not on/off")


def _safety(env: Mapping[str, str]) -> SafetyParams:
    d = SafetyParams()
    return SafetyParams(
        enabled=_switch(env, "PNAV_BRIDGE_SAFETY", d.enabled),
        decel_mps2=_optional_positive(env, "PNAV_BRIDGE_SAFETY_DECEL_MPS2"),
        latency_s=_non_negative(env, "PNAV_BRIDGE_SAFETY_LATENCY_S", d.latency_s),
        margin_m=_non_negative(env, "PNAV_BRIDGE_SAFETY_MARGIN_M", d.margin_m),
        scan_max_age_s=_positive(env, "PNAV_BRIDGE_SAFETY_SCAN_AGE_S", d.scan_max_age_s),
        blind_mps=_non_negative(env, "PNAV_BRIDGE_SAFETY_BLIND_MPS", d.blind_mps),
    )


@dataclass(frozen=True)
class BridgeSettings:
    # The TurtleBot3 firmware's heartbeat and ROS diff_drive_controller both time out at 0.5 s.
    watchdog_s: float = 0.5
    command_period_s: float = 0.05
    # how often the watchdog looks at the clock (wall); bounds how late a stop can be
    watchdog_tick_s: float = 0.02
    prune_period_s: float = 5.0
    stats_period_s: float = 10.0
    # while no world has been applied, ask the sim's queryable again this often
    world_retry_s: float = 2.0
    # rows waiting per table while Postgres is slow; beyond it the oldest are dropped
    max_pending_rows: int = 10_000
    safety: SafetyParams = field(default_factory=SafetyParams)
    # `pnav bench latency --robot-link ros2`: which command id went out as which cmd_vel
    trace: str | None = None

    def __post_init__(self) -> None:
        for name in ("watchdog_s", "command_period_s", "watchdog_tick_s", "prune_period_s"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"bridge setting {name} must be positive")
        if self.max_pending_rows < 1:
            raise ConfigError("bridge setting max_pending_rows must be at least 1")

    @classmethod
    def from_env(cls, env: Mapping[str, str] | None = None) -> BridgeSettings:
        env = os.environ if env is None else env
        return cls(
            watchdog_s=_positive(env, "PNAV_BRIDGE_WATCHDOG_S", cls.watchdog_s),
            command_period_s=_positive(
                env, "PNAV_BRIDGE_COMMAND_PERIOD_MS", cls.command_period_s, 1e-3
            ),
            prune_period_s=_positive(env, "PNAV_BRIDGE_PRUNE_PERIOD_S", cls.prune_period_s),
            stats_period_s=_positive(env, "PNAV_BRIDGE_STATS_PERIOD_S", cls.stats_period_s),
            safety=_safety(env),
            trace=env.get("PNAV_BRIDGE_TRACE", "").strip() or None,
        )

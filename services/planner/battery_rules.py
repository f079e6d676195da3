"""The planner's battery rules: CMD_BATTSAVE when the charge will not last, CMD_RESUME when
charging is done.

- ``BatteryCheck`` (strategies whose target is the goal, with ``battery_wh_per_m``): if the
  newest battery ``energy_wh`` is below the remaining path length x ``battery_wh_per_m`` +
  ``battery_reserve_wh``, recommend the system command CMD_BATTSAVE (source battery_check,
  priority 60, valid 2 s), never while one of this robot's is still unexpired.
- ``ChargeComplete`` (strategies whose target is the nearest charger): once the battery is
  at ``resume_at_pct`` percent, or holds ``resume_margin`` x (energy from the station to the
  active goal along the path + reserve), recommend CMD_RESUME (source charge_complete,
  priority 50, valid 2 s), once per charging session. As a safety net, if the strategy is
  still the charging one RESUME_RETRY_S after that recommendation expired (the command was
  lost), it is recommended again.

The arithmetic is in plain functions, unit-tested on their own.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from typing import Any, ClassVar

from common import log
from common.contract import records
from services.planner.routes import Target
from services.planner.scenario import ODOM_MAX_AGE_S
from services.planner.target import RuleKey, Spec, TargetRule
from services.planner.view import PlannerView
from services.planner.world_model import RobotState

logger = logging.getLogger("pnav.planner")

CMD_BATTSAVE = "CMD_BATTSAVE"
CMD_RESUME = "CMD_RESUME"
BATTSAVE_PRIORITY = 60
RESUME_PRIORITY = 50
VALIDITY_S = 2.0
BATTERY_MAX_AGE_S = 5.0  # the sim reports the battery at 1 Hz
RESUME_RETRY_S = 10.0
# The battery is reported at 1 Hz: looking at it on every odometry wake-up (30 Hz) would only
# cost queries. Seconds of the store's clock between two evaluations.
EVAL_PERIOD_S = 0.2
CHARGE_CODE = "CHARGE"


def energy_needed(distance_m: float, wh_per_m: float, reserve_wh: float) -> float:
    """Wh to drive ``distance_m`` and still hold the reserve."""
    return max(0.0, distance_m) * wh_per_m + reserve_wh


def needs_charge(energy_wh: float, distance_m: float, wh_per_m: float, reserve_wh: float) -> bool:
    """True if the charge left will not cover the distance plus the reserve."""
    return energy_wh < energy_needed(distance_m, wh_per_m, reserve_wh)


def charged_enough(
    percentage: float,
    energy_wh: float,
    resume_at_pct: float | None,
    resume_margin: float | None,
    need_wh: float | None,
) -> bool:
    """CHARGE is done at ``resume_at_pct`` percent, or with ``resume_margin`` times the energy
    the rest of the mission needs (``need_wh``, None when there is no goal to go back to)."""
    if resume_at_pct is not None and percentage >= resume_at_pct:
        return True
    return (
        resume_margin is not None and need_wh is not None and energy_wh >= resume_margin * need_wh
    )


def number(params: dict[str, Any], key: str) -> float | None:
    """A numeric strategy param, None when absent or not a number."""
    value = params.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value)


class _BatteryRule(TargetRule):
    kind: ClassVar[str] = "battery"

    def __init__(self, view: PlannerView, key: RuleKey, spec: Spec) -> None:
        super().__init__(view, key, spec)
        self.quiet_until = float("-inf")  # sim time before which we do not recommend again
        self.robot: RobotState | None = None
        self.params: dict[str, Any] = {}
        self.battery: records.Battery | None = None
        self.odom: records.Odometry | None = None
        self.goal: records.Goal | None = None
        self.sim_now = 0.0
        self.ready = False  # this activation read fresh inputs
        self._next_eval = 0.0

    async def _read(self) -> bool:
        self.ready = False
        self.robot = self.claim()
        if self.robot is None or self.robot.strategy is None:
            return False
        view = self.view
        if view.clock() < self._next_eval:
            return False
        self._next_eval = view.clock() + EVAL_PERIOD_S
        self.ready = True
        self.params = self.robot.strategy.params
        self.sim_now = view.now()
        self.battery = await view.newest_battery(self.robot_id)
        self.odom = await view.newest_odometry(self.robot_id)
        self.goal = await view.active_goal(self.robot)
        return True

    def _fresh(self, stamp: float, max_age: float) -> bool:
        return self.view.started() and self.sim_now - stamp <= max_age

    async def _recommend(self, command: str, source: str, priority: int, reason: str) -> None:
        """Write the recommendation unless one is still live (ours from before a restart, or
        another replica's); either way stay quiet until it expires."""
        live_until = await self.view.live_system(self.robot_id, command)
        if live_until is not None:
            self.quiet_until = live_until
            return
        assert self.battery is not None
        stamp = max(self.battery.stamp, self.odom.stamp if self.odom else self.battery.stamp)
        inputs: dict[str, Any] = {"battery": self.battery.id, "battery_stamp": self.battery.stamp}
        if self.odom is not None:
            inputs["odometry"] = self.odom.id
        if self.goal is not None:
            inputs["goal"] = self.goal.id
        await self.view.recommend_system(
            self.robot_id,
            source=source,
            priority=priority,
            command=command,
            stamp=stamp,
            ttl_s=VALIDITY_S,
            reason=reason,
            inputs=inputs,
        )
        self.quiet_until = stamp + VALIDITY_S
        log.event(
            logger,
            logging.INFO,
            "system command recommended",
            robot=self.robot_id,
            command=command,
            reason=reason,
        )


class BatteryCheck(_BatteryRule):
    scenario = "battery_check"

    def __init__(self, view: PlannerView, key: RuleKey, spec: Spec) -> None:
        super().__init__(view, key, spec)
        self.need_wh = 0.0
        self.remaining_m = 0.0
        self.wh_per_m = 0.0
        self.reserve_wh = 0.0

    async def data_acquisition(self) -> None:
        if not await self._read():
            return
        assert self.robot is not None
        if self.odom is not None and self.goal is not None:
            target = Target.of_goal(self.goal)
            progress = self.view.route_for(self.robot, self.odom.x, self.odom.y, target)
            self.remaining_m = progress.remaining_m
        self.wh_per_m = number(self.params, "battery_wh_per_m") or 0.0
        self.reserve_wh = number(self.params, "battery_reserve_wh") or 0.0
        self.need_wh = energy_needed(self.remaining_m, self.wh_per_m, self.reserve_wh)

    def activation_guards(self) -> Iterator[bool]:
        yield self.ready
        assert self.robot is not None and self.robot.strategy is not None
        yield self.robot.strategy.code != CHARGE_CODE
        yield self.params.get("target") == "goal"
        yield number(self.params, "battery_wh_per_m") is not None
        yield self.goal is not None
        yield self.odom is not None and self._fresh(self.odom.stamp, ODOM_MAX_AGE_S)
        yield self.battery is not None and self._fresh(self.battery.stamp, BATTERY_MAX_AGE_S)

    def conditions(self) -> Iterator[bool]:
        assert self.battery is not None
        yield self.sim_now >= self.quiet_until
        yield needs_charge(self.battery.energy_wh, self.remaining_m, self.wh_per_m, self.reserve_wh)

    async def actions(self) -> None:
        assert self.battery is not None
        await self._recommend(
            CMD_BATTSAVE,
            "battery_check",
            BATTSAVE_PRIORITY,
            f"{self.battery.energy_wh:.3f} Wh left < {self.need_wh:.3f} Wh needed for "
            f"{self.remaining_m:.2f} m to goal {self.goal.id if self.goal else '?'} + reserve",
        )


class ChargeComplete(_BatteryRule):
    scenario = "charge_complete"

    def __init__(self, view: PlannerView, key: RuleKey, spec: Spec) -> None:
        super().__init__(view, key, spec)
        self.need_wh: float | None = None
        self._need_key: tuple[Any, ...] | None = None
        self._need_m = 0.0

    async def data_acquisition(self) -> None:
        if not await self._read():
            return
        assert self.robot is not None
        station = self.robot.station
        if station is None and self.odom is not None:
            station = self.view.choose_station(self.robot, self.odom.x, self.odom.y)
        self.need_wh = None
        wh_per_m = number(self.params, "battery_wh_per_m")
        if self.goal is None or wh_per_m is None:
            return
        if station is not None:
            start = (station.x, station.y)
        elif self.odom is not None:
            start = (self.odom.x, self.odom.y)
        else:
            return
        # The station-to-goal path is planned once per (station, goal, map).
        data = self.view.map_for(self.robot.info)
        key = (start, self.goal.id, data.version if data else None)
        if key != self._need_key:
            self._need_key = key
            self._need_m = self.view.distance(self.robot, start, (self.goal.x, self.goal.y))
        reserve = number(self.params, "battery_reserve_wh") or 0.0
        self.need_wh = energy_needed(self._need_m, wh_per_m, reserve)

    def activation_guards(self) -> Iterator[bool]:
        yield self.ready
        yield self.params.get("target") == "nearest_charger"
        yield self.battery is not None and self._fresh(self.battery.stamp, BATTERY_MAX_AGE_S)

    def conditions(self) -> Iterator[bool]:
        assert self.battery is not None
        # once per session: quiet_until is the last recommendation's expiry (+ the retry delay)
        yield self.sim_now >= self.quiet_until
        yield charged_enough(
            self.battery.percentage,
            self.battery.energy_wh,
            number(self.params, "resume_at_pct"),
            number(self.params, "resume_margin"),
            self.need_wh,
        )

    async def actions(self) -> None:
        assert self.battery is not None
        need = f", {self.need_wh:.3f} Wh needed to the goal" if self.need_wh is not None else ""
        await self._recommend(
            CMD_RESUME,
            "charge_complete",
            RESUME_PRIORITY,
            f"charged: {self.battery.percentage:.1f} % ({self.battery.energy_wh:.3f} Wh){need}",
        )
        # Ours or one already live: either way this session has its CMD_RESUME.
        self.quiet_until += RESUME_RETRY_S

"""The base of every controller scenario: a target rule per (robot, scenario) that lives while
the robot's strategy names the scenario, and recommends on each fresh scan.

A scenario class only says *what* to recommend, in :meth:`ControllerScenario.decide`, a pure
function of the scan, the odometry, the robot's limits and the strategy's params (unit tests
drive it tick by tick). The base does the rest the same way for every scenario:

1. data acquisition: the robot's newest laser scan; if it is one to act on (new to this
   scenario, fresh), the odometry read with it (if ``needs_odometry``) and ``decide``'s
   command for it;
2. activation guards: the scenario is still wanted (it is live), the scan is one
   this scenario has not recommended on yet, and it is fresh (stamp within
   ``scan_max_age_s`` of sim now);
3. conditions: ``decide`` returned a command;
4. actions: write the recommendation (priority, validity from the scan's stamp, inputs);
5. rule generation: the same object again, while the meta-controller's supervisor keeps it
   running (a :class:`~common.engine.Behaviour`: ``initialise`` when its robot's strategy
   names it, ``terminate`` when that ends; what it keeps between scans lives in ``self``).

Scenarios are found, not listed: the controller loads every class named under the
entry-point group :data:`SCENARIO_GROUP` when it starts (docs/CONTROLLER.md, "Adding a
controller scenario"). This module lives in common/ so that a scenario package needs
nothing of the controller service's: the service implements :class:`Host` and runs the
scenarios.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

from common import log
from common.contract.models import RegisteredModel
from common.contract.planned_path import PlannedPath
from common.contract.recommendations import Recommendation
from common.contract.records import ActiveStrategy, LaserScan, Odometry, Robot
from common.controller_core.params import number
from common.engine.behaviour import Behaviour
from common.errors import InternalError
from common.plugins import load_scenarios

logger = logging.getLogger("pnav.controller")

# The entry-point group that names the controller scenarios (name = what strategies list).
SCENARIO_GROUP = "pnav.controller.scenarios"

# A scan older than this (sim s) describes a world that has moved on: recommend nothing.
DEFAULT_SCAN_MAX_AGE_S = 0.5

Key = tuple[str, str]  # (robot id, scenario name): one running scenario


@dataclass(frozen=True)
class Command:
    """What a scenario recommends: a velocity, and why (for people)."""

    linear: float
    angular: float
    reason: str
    # more provenance for the row's ``inputs`` (e.g. the planned_path a local controller
    # scored against), beside the scan and odometry the base names
    inputs: Mapping[str, Any] | None = None


@dataclass(frozen=True)
class ScenarioSpec:
    """What a running scenario follows: its robot (limits), the strategy naming it, and the
    strategy's params. A change is applied in place (``Behaviour.reconfigure``)."""

    robot: Robot
    strategy: str
    params: Mapping[str, Any]


class Host(Protocol):
    """What the rules see of their service: the controller's store
    (services/controller/store.py), or any object with these methods."""

    def sim_now(self) -> float | None:
        """Sim time now, or None before the first clock message."""

    async def robots(self) -> list[Robot]: ...

    async def active_strategies(self) -> dict[str, ActiveStrategy]: ...

    async def newest_scan(self, robot_id: str) -> LaserScan | None: ...

    async def odometry_at(self, scan: LaserScan) -> Odometry | None:
        """The robot's odometry as of ``scan``: its motion when the scan was read, which is
        what a decision about the scan needs."""

    async def planned_path(self, robot_id: str) -> PlannedPath | None:
        """The path in force for the robot (the planner's newest planned_path row), for the
        local controllers that score against it."""

    async def registered_model(self, name: str, version: str | None) -> RegisteredModel | None:
        """The ``model`` table's row (name, version), or with no version the newest
        registered under ``name``; None: not registered (common.contract.models). Read again
        every few seconds, or at once when notified: a learned scenario's model is switched
        by an UPDATE of the strategy (or a new row), with no restart."""

    def last_recommended_scan(self, robot_id: str, source: str) -> int | None:
        """The newest scan ``source`` recommended on for the robot (this tenure), if any."""

    async def recommend(self, recommendation: Recommendation) -> None:
        """Write the recommendation (the controller's store holds it until the end of the
        activation and writes the activation's rows in one statement)."""


class ControllerScenario(Behaviour[Key, ScenarioSpec]):
    """Base target rule; subclasses set ``scenario``, ``priority`` and ``decide``."""

    scenario: ClassVar[str] = ""
    priority: ClassVar[int] = 0
    validity_s: ClassVar[float] = 0.5  # CONTRACT.md, "Conventions the shipped scenarios follow"
    needs_odometry: ClassVar[bool] = False

    def __init__(self, host: Host, key: Key, spec: ScenarioSpec) -> None:
        super().__init__(key, spec)
        self.robot_id = key[0]  # a wake for this robot runs it (docs/ENGINE.md)
        self.host = host
        self.now: float | None = None
        self.scan: LaserScan | None = None
        self.odom: Odometry | None = None
        self.command: Command | None = None
        self.failure: Exception | None = None

    @classmethod
    def decide(
        cls, scan: LaserScan, odom: Odometry | None, robot: Robot, params: Mapping[str, Any]
    ) -> Command | None:
        """The scenario's policy: a command for this scan, or None to stay silent. A
        scenario that decides in its own ``judge`` (dwa with its path, dodge with its tracks,
        the learned ones with their model) is silent here; one that overrides neither has
        no policy."""
        if cls.judge is ControllerScenario.judge:
            raise NotImplementedError
        return None

    def judge(self, scan: LaserScan, odom: Odometry | None) -> Command | None:
        """The command for ``scan``: ``decide``'s with the spec's robot and params. A
        scenario that also uses what it read in its own acquisition (a local controller's
        planned path) overrides this."""
        spec = self.spec
        return self.decide(scan, odom, spec.robot, spec.params)

    def ttl_s(self) -> float:
        """How long this recommendation stays valid (sim s): ``validity_s``, unless the
        scenario knows better (dodge: a few scan periods, so a yield ends with its threat)."""
        return self.validity_s

    # -- lifecycle (common.engine.behaviour) ---------------------------------------------------
    def initialise(self) -> None:
        self._log("controller scenario started")

    def terminate(self, why: str) -> None:
        self._log("controller scenario ended", why=why)

    # -- the five steps ------------------------------------------------------------------------
    async def data_acquisition(self) -> None:
        self.scan, self.odom, self.command, self.failure = None, None, None, None
        self.now = self.host.sim_now()
        if not self.live:
            return
        spec = self.spec
        scan = self.scan = await self.host.newest_scan(spec.robot.robot_id)
        if scan is None or not self._new_fresh_scan():
            return  # most activations see no new scan: nothing more to read or judge
        if self.needs_odometry:
            self.odom = await self.host.odometry_at(scan)
        # ``decide`` is judged here, once, so that the guards and conditions only test. Its
        # error is kept for conditions to raise: a failing policy counts as a false test
        # there (logged, counted; the rule lives on), as it did when conditions called it.
        try:
            self.command = self.judge(scan, self.odom)
        except Exception as exc:
            self.failure = exc

    def activation_guards(self) -> Iterator[bool]:
        yield self.live
        yield self._new_fresh_scan()

    def conditions(self) -> bool:
        if self.failure is not None:
            raise self.failure
        return self.command is not None

    async def actions(self) -> None:
        scan, command = self.scan, self.command
        if scan is None or command is None:
            raise InternalError(f"{self.name}: actions ran without a scan and a command")
        inputs: dict[str, Any] = {"laser_scan": scan.id, "scan_stamp": scan.stamp}
        if self.odom is not None:
            inputs.update(odometry=self.odom.id, odometry_stamp=self.odom.stamp)
        if command.inputs:
            inputs.update(command.inputs)
        await self.host.recommend(
            Recommendation.velocity(
                self.spec.robot.robot_id,
                source=self.scenario,
                priority=self.priority,
                linear=command.linear,
                angular=command.angular,
                stamp=scan.stamp,  # the newest input's sim time; expires ttl_s() later
                ttl_s=self.ttl_s(),
                reason=command.reason,
                inputs=inputs,
            )
        )

    # -- helpers -------------------------------------------------------------------------------
    def _new_fresh_scan(self) -> bool:
        scan, now, spec = self.scan, self.now, self.spec
        if scan is None or now is None:
            return False
        if scan.id == self.host.last_recommended_scan(spec.robot.robot_id, self.scenario):
            return False
        max_age = number(spec.params, "scan_max_age_s", DEFAULT_SCAN_MAX_AGE_S)
        # abs(): our clock may trail the sim's by a few ms, so a new scan can look "early".
        return abs(now - scan.stamp) <= max_age

    def _log(self, message: str, **fields: Any) -> None:
        spec = self.spec
        log.event(
            logger,
            logging.INFO,
            message,
            robot=spec.robot.robot_id,
            scenario=self.scenario,
            strategy=spec.strategy,
            **fields,
        )

    def __repr__(self) -> str:
        return f"<{self.name} robot={self.spec.robot.robot_id} live={self.live}>"


def installed_scenarios() -> dict[str, type[ControllerScenario]]:
    """Every controller scenario the installed packages name (common.plugins)."""
    return load_scenarios(SCENARIO_GROUP, ControllerScenario)

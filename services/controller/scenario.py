"""The base of every controller scenario: a target rule per (robot, scenario) that clones
itself while the robot's strategy names the scenario, and recommends on each fresh scan.

A scenario class only says *what* to recommend, in :meth:`ControllerScenario.decide`, a pure
function of the scan, the odometry, the robot's limits and the strategy's params (unit tests
drive it tick by tick). The base does the rest the same way for every scenario:

1. data acquisition: the robot's newest laser scan (and odometry if ``needs_odometry``);
2. activation guards: the scenario is still wanted, the scan is one this scenario has not
   recommended on yet, and it is fresh (stamp within ``scan_max_age_s`` of sim now);
3. conditions: ``decide`` returns a command;
4. actions: write the recommendation (priority, validity from the scan's stamp, inputs);
5. rule generation: a clone, while the meta-controller keeps the scenario active.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

from common.contract.records import ActiveStrategy, LaserScan, Odometry, Robot
from common.engine import Rule
from services.controller.params import number

# A scan older than this (sim s) describes a world that has moved on: recommend nothing.
DEFAULT_SCAN_MAX_AGE_S = 0.5


@dataclass(frozen=True)
class Command:
    """What a scenario recommends: a velocity, and why (for people)."""

    linear: float
    angular: float
    reason: str


@dataclass(frozen=True)
class Recommendation:
    """A row of command_recommendation (kind ``robot``) about to be written."""

    robot_id: str
    source: str
    priority: int
    linear: float
    angular: float
    stamp: float
    ttl_s: float
    reason: str
    inputs: dict[str, Any]


class Host(Protocol):
    """What the rules need from their service; unit tests pass an in-memory fake."""

    def sim_now(self) -> float | None:
        """Sim time now, or None before the first clock message."""

    async def robots(self) -> list[Robot]: ...

    async def active_strategies(self) -> dict[str, ActiveStrategy]: ...

    async def newest_scan(self, robot_id: str) -> LaserScan | None: ...

    async def newest_odometry(self, robot_id: str) -> Odometry | None: ...

    async def recommend(self, recommendation: Recommendation) -> int: ...


@dataclass(eq=False)
class Handle:
    """One running scenario of one robot. The meta-controller owns it (ends it, updates its
    strategy and limits); the target rule and its clones read it and live while it is active."""

    robot: Robot
    strategy: str
    params: Mapping[str, Any]
    active: bool = True
    last_scan_id: int | None = None  # the newest scan this scenario recommended on
    beats: int = 0  # rule generations so far: how the meta-controller sees a lost rule
    seen_beats: int = -1  # beats at the meta-controller's previous look
    stalled: int = 0  # meta-controller runs in a row that saw no beat


class ControllerScenario(Rule):
    """Base target rule; subclasses set ``scenario``, ``priority`` and ``decide``."""

    scenario: ClassVar[str] = ""
    priority: ClassVar[int] = 0
    validity_s: ClassVar[float] = 0.5  # CONTRACT.md, "Conventions the shipped scenarios follow"
    needs_odometry: ClassVar[bool] = False

    def __init__(self, host: Host, handle: Handle) -> None:
        self.host = host
        self.handle = handle
        self.now: float | None = None
        self.scan: LaserScan | None = None
        self.odom: Odometry | None = None
        self.command: Command | None = None

    @classmethod
    def decide(
        cls, scan: LaserScan, odom: Odometry | None, robot: Robot, params: Mapping[str, Any]
    ) -> Command | None:
        """The scenario's policy: a command for this scan, or None to stay silent."""
        raise NotImplementedError

    # -- the five steps ----------------------------------------------------------------------
    async def data_acquisition(self) -> None:
        self.scan, self.odom, self.command = None, None, None
        self.now = self.host.sim_now()
        if not self.handle.active:
            return
        robot_id = self.handle.robot.robot_id
        self.scan = await self.host.newest_scan(robot_id)
        # Odometry only when the scan will be used: most activations see no new scan.
        if self.needs_odometry and self._new_fresh_scan():
            self.odom = await self.host.newest_odometry(robot_id)

    def activation_guards(self) -> Iterator[bool]:
        yield self.handle.active
        yield self._new_fresh_scan()

    def conditions(self) -> Iterator[bool]:
        assert self.scan is not None  # the guards held
        # ``decide`` is pure; its result is kept for actions rather than computed twice.
        self.command = self.decide(self.scan, self.odom, self.handle.robot, self.handle.params)
        yield self.command is not None

    async def actions(self) -> None:
        scan, command = self.scan, self.command
        assert scan is not None and command is not None
        inputs: dict[str, Any] = {"laser_scan": scan.id, "scan_stamp": scan.stamp}
        if self.odom is not None:
            inputs.update(odometry=self.odom.id, odometry_stamp=self.odom.stamp)
        await self.host.recommend(
            Recommendation(
                robot_id=self.handle.robot.robot_id,
                source=self.scenario,
                priority=self.priority,
                linear=command.linear,
                angular=command.angular,
                stamp=scan.stamp,  # the newest input's sim time; expires validity_s later
                ttl_s=self.validity_s,
                reason=command.reason,
                inputs=inputs,
            )
        )
        self.handle.last_scan_id = scan.id

    def rule_generation(self) -> list[Rule]:
        self.handle.beats += 1
        return [self.clone()] if self.handle.active else []

    # -- helpers -----------------------------------------------------------------------------
    def _new_fresh_scan(self) -> bool:
        scan, now = self.scan, self.now
        if scan is None or now is None or scan.id == self.handle.last_scan_id:
            return False
        max_age = number(self.handle.params, "scan_max_age_s", DEFAULT_SCAN_MAX_AGE_S)
        # abs(): our clock may trail the sim's by a few ms, so a new scan can look "early".
        return abs(now - scan.stamp) <= max_age

    def __repr__(self) -> str:
        return f"<{self.name} robot={self.handle.robot.robot_id} active={self.handle.active}>"

"""The meta-controller (thesis, "Controller Scenario"): per robot, keep running exactly the
controller scenarios its strategy names, any number at once.

It is a continuous meta rule: every activation (a notification on active_strategy, strategy,
laser_scan or robot wakes the engine, and the period F is the fallback) it reads the robots
and their active strategies and compares the scenarios they name with those running:

- a newly named scenario starts: a fresh target rule with its own :class:`Handle`;
- a scenario no longer named (or whose robot left, or is now owned by another replica of
  the controller, docs/REPLICAS.md) ends: its handle goes inactive, so its
  target rule recommends nothing more and stops cloning itself;
- a scenario still named follows the strategy's new params and the robot's new limits;
- an unknown name is logged once and ignored;
- a target rule that no longer runs (the engine discards a rule whose data acquisition or
  actions failed, e.g. while the database restarts) is replaced, so a lost connection never
  silently ends safety_stop.

Its state lives in :class:`ControllerState`, outside the rule, so a meta rule the engine
re-seeds after an error carries on with the scenarios already running.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from common import log
from common.contract import keys
from common.contract.records import ActiveStrategy, Robot
from common.engine import Rule
from services.controller.registry import SCENARIOS
from services.controller.scenario import ControllerScenario, Handle, Host

logger = logging.getLogger("pnav.controller")

Key = tuple[str, str]  # (robot id, scenario name)

# Meta runs in a row without a generation of a target rule before it is deemed lost. A rule
# left over by the engine's N cap runs first in the next activation, so a live rule is never
# this late.
STALL_LIMIT = 20


@dataclass
class ControllerState:
    running: dict[Key, Handle] = field(default_factory=dict)
    # The newest scan each ended scenario recommended on: a restarted scenario does not
    # recommend again on a scan it already used.
    last_scan: dict[Key, int] = field(default_factory=dict)
    unknown: set[str] = field(default_factory=set)


@dataclass(frozen=True)
class Wanted:
    robot: Robot
    strategy: str
    params: Mapping[str, object]


class MetaController(Rule):
    scenario = "meta_controller"
    meta = True
    watches = (keys.ACTIVE_STRATEGY, keys.STRATEGY, keys.LASER_SCAN, keys.ROBOT)

    def __init__(
        self,
        host: Host,
        state: ControllerState,
        scenarios: Mapping[str, type[ControllerScenario]] = SCENARIOS,
        owns: Callable[[str], bool] = lambda _robot_id: True,
    ) -> None:
        self.host = host
        self.state = state
        self.scenarios = scenarios
        self.owns = owns  # replicas: run scenarios only for the robots this one owns
        self.wanted: dict[Key, Wanted] = {}
        self.starts: list[Key] = []
        self.ends: list[Key] = []
        self.updates: list[Key] = []
        self.lost: list[Key] = []
        self.generated: list[Rule] = []

    async def data_acquisition(self) -> None:
        self.generated = []
        active = await self.host.active_strategies()
        robots = {robot.robot_id: robot for robot in await self.host.robots()}
        self.wanted = self._wanted(active, robots)

    def activation_guards(self) -> bool:
        return True  # every activation compares what should run with what runs

    def conditions(self) -> bool:
        running = self.state.running
        self.starts = [key for key in self.wanted if key not in running]
        self.ends = [key for key in running if key not in self.wanted]
        self.updates = [
            key
            for key, want in self.wanted.items()
            if key in running and _differs(running[key], want)
        ]
        self.lost = [key for key in self.wanted if key in running and _stalled(running[key])]
        return bool(self.starts or self.ends or self.updates or self.lost)

    def actions(self) -> None:
        for key in self.ends:
            self._end(key, "no longer in the strategy")
        for key in self.lost:
            self._end(key, "its rule was lost")
            self._start(key, "restarted")
        for key in self.starts:
            self._start(key, "started")
        for key in self.updates:
            handle, want = self.state.running[key], self.wanted[key]
            handle.robot, handle.strategy, handle.params = want.robot, want.strategy, want.params

    def rule_generation(self) -> list[Rule]:
        # Clone first: the meta-controller stays at the head of the queue, so in every
        # activation it applies a strategy switch before any target rule reads a scan.
        return [self.clone(), *self.generated]

    # -- helpers -------------------------------------------------------------------------
    def _wanted(
        self, active: dict[str, ActiveStrategy], robots: dict[str, Robot]
    ) -> dict[Key, Wanted]:
        wanted: dict[Key, Wanted] = {}
        for robot_id, current in sorted(active.items()):
            robot = robots.get(robot_id)
            if robot is None or not self.owns(robot_id):
                continue  # gone, or served by another replica: its scenarios end
            strategy = current.strategy
            for name in strategy.controller_scenarios:
                if name not in self.scenarios:
                    if name not in self.state.unknown:
                        self.state.unknown.add(name)
                        log.event(
                            logger,
                            logging.WARNING,
                            "unknown controller scenario ignored",
                            scenario=name,
                            strategy=strategy.code,
                            known=",".join(sorted(self.scenarios)),
                        )
                    continue
                wanted[(robot_id, name)] = Wanted(robot, strategy.code, strategy.params)
        return wanted

    def _start(self, key: Key, why: str) -> None:
        want = self.wanted[key]
        handle = Handle(want.robot, want.strategy, want.params)
        handle.last_scan_id = self.state.last_scan.pop(key, None)
        self.state.running[key] = handle
        self.generated.append(self.scenarios[key[1]](self.host, handle))
        log.event(
            logger,
            logging.INFO,
            f"controller scenario {why}",
            robot=key[0],
            scenario=key[1],
            strategy=want.strategy,
        )

    def _end(self, key: Key, why: str) -> None:
        handle = self.state.running.pop(key)
        handle.active = False
        if handle.last_scan_id is not None:
            self.state.last_scan[key] = handle.last_scan_id
        log.event(
            logger,
            logging.INFO,
            "controller scenario ended",
            robot=key[0],
            scenario=key[1],
            strategy=handle.strategy,
            why=why,
        )


def _differs(handle: Handle, want: Wanted) -> bool:
    return (handle.robot, handle.strategy, handle.params) != (
        want.robot,
        want.strategy,
        want.params,
    )


def _stalled(handle: Handle) -> bool:
    """Count meta runs without a generation of the handle's rule; True once it is lost."""
    if handle.beats != handle.seen_beats:
        handle.seen_beats, handle.stalled = handle.beats, 0
        return False
    handle.stalled += 1
    return handle.stalled > STALL_LIMIT

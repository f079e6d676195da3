"""The meta-controller (thesis, "Controller Scenario"): per robot, keep running exactly the
controller scenarios its strategy names, any number at once.

It is a continuous meta rule: every activation (a notification on active_strategy, strategy,
laser_scan or robot wakes the engine, and the period F is the fallback) it reads the robots
and their active strategies, works out which (robot, scenario) pairs are wanted and with
which spec (robot, strategy code, params), and hands that to a
:class:`~common.engine.supervisor.Supervisor`, which

- starts a newly named scenario: a fresh target rule (a ``Behaviour``, initialised once);
- ends a scenario no longer named (or whose robot left, or is now owned by another replica
  of the controller, docs/REPLICAS.md): it is terminated, recommends nothing more and
  leaves the queue;
- updates a scenario still named in place when the strategy's params or the robot's limits
  change;
- restarts a target rule the engine discarded on an error (e.g. while the database
  restarts), at its next run, so a lost connection never silently ends safety_stop.

An unknown name is logged once and ignored. What a scenario recommended on survives any of
this: the store remembers the newest scan each (robot, scenario) recommended on.

Its state (the supervisor, the names already warned about) lives in
:class:`ControllerState`, outside the rule, so a meta rule the engine re-seeds after an
error carries on with the scenarios already running.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from common import log
from common.contract import keys
from common.contract.records import ActiveStrategy, Robot
from common.controller_core.scenario import ControllerScenario, Host, Key, ScenarioSpec
from common.engine import Behaviour, Engine, Rule, Supervisor

logger = logging.getLogger("pnav.controller")

Scenarios = Mapping[str, type[ControllerScenario]]


@dataclass
class ControllerState:
    """What the meta-controller keeps across its runs (and across a re-seed)."""

    supervisor: Supervisor[Key, ScenarioSpec]
    scenarios: Scenarios
    unknown: set[str] = field(default_factory=set)  # names already warned about


class MetaController(Rule):
    scenario = "meta_controller"
    meta = True
    watches = (keys.ACTIVE_STRATEGY, keys.STRATEGY, keys.LASER_SCAN, keys.ROBOT)

    def __init__(
        self,
        host: Host,
        state: ControllerState,
        owns: Callable[[str], bool] = lambda _robot_id: True,
    ) -> None:
        self.host = host
        self.state = state
        self.owns = owns  # replicas: run scenarios only for the robots this one owns
        self.wanted: dict[Key, ScenarioSpec] = {}
        self.generated: list[Rule] = []

    async def data_acquisition(self) -> None:
        self.generated = []
        active = await self.host.active_strategies()
        robots = {robot.robot_id: robot for robot in await self.host.robots()}
        self.wanted = self._wanted(active, robots)

    def activation_guards(self) -> bool:
        return True  # every activation compares what should run with what runs

    def conditions(self) -> bool:
        return out_of_date(self.state.supervisor.running, self.wanted)

    def actions(self) -> None:
        self.generated = self.state.supervisor.reconcile(self.wanted)

    def rule_generation(self) -> list[Rule]:
        # Clone first: the meta-controller stays at the head of the queue, so in every
        # activation it applies a strategy switch before any target rule reads a scan.
        return [self.clone(), *self.generated]

    # -- helpers -------------------------------------------------------------------------
    def _wanted(
        self, active: dict[str, ActiveStrategy], robots: dict[str, Robot]
    ) -> dict[Key, ScenarioSpec]:
        wanted: dict[Key, ScenarioSpec] = {}
        for robot_id, current in sorted(active.items()):
            robot = robots.get(robot_id)
            if robot is None or not self.owns(robot_id):
                continue  # gone, or served by another replica: its scenarios end
            strategy = current.strategy
            for name in strategy.controller_scenarios:
                if name in self.state.scenarios:
                    wanted[(robot_id, name)] = ScenarioSpec(robot, strategy.code, strategy.params)
                else:
                    self._unknown(name, strategy.code)
        return wanted

    def _unknown(self, name: str, strategy: str) -> None:
        if name in self.state.unknown:
            return
        self.state.unknown.add(name)
        log.event(
            logger,
            logging.WARNING,
            "unknown controller scenario ignored",
            scenario=name,
            strategy=strategy,
            known=",".join(sorted(self.state.scenarios)),
        )


def out_of_date(
    running: Mapping[Key, Behaviour[Key, ScenarioSpec]], wanted: Mapping[Key, ScenarioSpec]
) -> bool:
    """Whether ``Supervisor.reconcile(wanted)`` has anything to do (start, end, restart,
    update): a pure test, for the meta rule's conditions."""
    if running.keys() != wanted.keys():
        return True
    return any(rule.lost or rule.spec != wanted[key] for key, rule in running.items())


def seed_controller(
    engine: Engine,
    host: Host,
    scenarios: Scenarios,
    owns: Callable[[str], bool] = lambda _robot_id: True,
) -> ControllerState:
    """Seed the meta-controller on ``engine``, running ``scenarios`` against ``host``; its
    state (for tests and the monolith to look at)."""

    def start(key: Key, spec: ScenarioSpec) -> ControllerScenario:
        return scenarios[key[1]](host, key, spec)

    state = ControllerState(Supervisor("controller", start), scenarios)
    engine.add_meta(lambda: MetaController(host, state, owns))
    return state

"""The navigation stack in one process: sim, bridge, controller, planner, decision.

What each part is made of (docs/MONOLITH.md has the whole list):

- controller: the service's own meta rule (``MetaController``) and scenario rules, seeded in
  an engine as ``ControllerService.seed`` does; :class:`ControllerHost` is the in-memory
  :class:`~services.controller.scenario.Host` (the protocol exists for exactly that) and
  reads through ``common.contract.records`` like the service;
- planner: ``PlannerState`` and ``MetaPlanner`` as ``PlannerService`` builds them, on a
  ``Database`` whose pool is the in-memory contract; the move and battery rules are the
  service's, unchanged;
- decision: a real ``DecisionService`` object (its ``MetaDecision`` and issue rules, hence
  ``decide_robot``/``decide_system``), on a ``Runtime`` that never connects: its database is
  the in-memory one, its sim clock is set from the sim every step;
- bridge: pnav/monolith/bridge.py; the strategy service is not run: the episode's strategy is
  written to ``active_strategy`` once, as ``SET_STRATEGY`` would, and no system command is
  acted on (none arises in a navigation episode: the battery starts full).

One :meth:`MonolithStack.step`: the sim senses and advances one physics step; its readings
become rows; then every engine that is due (a notification for a table it watches, a
``hurry``, or F = 50 ms of sim time since its last start) runs an activation, controller,
planner, decision in that order, and the bridge sends what was decided, until nothing more
is due. The command reaches the sim before its next physics step.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from common import bus
from common.config import ServiceConfig
from common.contract import keys, records
from common.db import Database
from common.runtime import Runtime
from pnav.monolith.bridge import Applied, Bridge
from pnav.monolith.contract import AdapterError, MemoryContract, MemoryNotifier
from pnav.monolith.engines import LockstepEngine
from pnav.monolith.sql import MemoryPool
from services.bridge.world import parse_world
from services.controller.meta import ControllerState, MetaController
from services.controller.scenario import Recommendation
from services.controller.service import store_recommendation
from services.decision.service import DecisionService
from services.planner.meta import MetaPlanner
from services.planner.state import PlannerState
from services.sim.sim import SimConfig, Simulation
from services.sim.world import World

GOAL_TOLERANCE_M = 0.15  # pnav.commands.set_goal's default, and the goal table's
MAX_PASSES = 50  # engine passes in one step before the loop is deemed to spin


class ControllerHost:
    """The controller rules' view of the contract, read through ``records`` as the service
    reads it (without its caches: a read here costs a dict lookup, not a round trip)."""

    def __init__(self, db: Database, now: Callable[[], float]) -> None:
        self.db = db
        self.now = now

    def sim_now(self) -> float | None:
        return self.now()

    async def robots(self) -> list[records.Robot]:
        return await records.robots(self.db.pool)

    async def active_strategies(self) -> dict[str, records.ActiveStrategy]:
        return await records.active_strategies(self.db.pool)

    async def newest_scan(self, robot_id: str) -> records.LaserScan | None:
        return await records.newest_scan(self.db.pool, robot_id)

    async def newest_odometry(self, robot_id: str) -> records.Odometry | None:
        return await records.newest_odometry(self.db.pool, robot_id)

    async def recommend(self, recommendation: Recommendation) -> int:
        return await store_recommendation(self.db, recommendation)


class MonolithStack:
    def __init__(
        self,
        world: World,
        config: SimConfig,
        strategies: list[records.Strategy],
        on_applied: Callable[[Applied], None] = lambda _applied: None,
        on_message: Callable[[str, str, dict[str, Any]], None] = lambda _r, _t, _m: None,
    ) -> None:
        self.now = 0.0  # sim time the logic sees: the sim's, after each step
        self.contract = MemoryContract()
        self.db = Database(MemoryPool(self.contract), MemoryNotifier(self.contract))
        self.on_message = on_message
        self._readings: list[tuple[str, str, dict[str, Any], float]] = []

        def sim_now() -> float:
            return self.now

        self.controller_state = ControllerState()
        host = ControllerHost(self.db, sim_now)
        self.controller = LockstepEngine("controller", sim_now)
        self.controller.add_meta(lambda: MetaController(host, self.controller_state))
        # the planner's own gates (re-reads, replanning, battery checks) count sim time
        # here, as they count wall time in the service at rate 1: deterministic runs
        self.planner_state = PlannerState(self.db, sim_now, lambda: True, wall=sim_now)
        self.planner = LockstepEngine("planner", sim_now)
        self.planner.add_meta(lambda: MetaPlanner(self.planner_state))
        runtime = Runtime(ServiceConfig(service="decision", database_url="memory://monolith"))
        runtime.db = self.db
        self.decision_service = DecisionService(runtime)
        self.decision = self.decision_service.engine = LockstepEngine("decision", sim_now)
        self.decision_service.seed()
        self.engines = (self.controller, self.planner, self.decision)
        # the tables each service subscribes to: those its meta rules watch
        self._watching = [(e, frozenset(e.watched_tables)) for e in self.engines]
        self.contract.listeners.append(self._notify)

        self.sim = Simulation(world, config, self._sink)
        self.bridge = Bridge(self.contract, self.sim.set_command, on_applied)
        self._load(world, strategies)

    # -- setting up the contract --------------------------------------------------------------
    def _load(self, world: World, strategies: list[records.Strategy]) -> None:
        """The rows the bridge writes from the sim's world message, and the strategy table."""
        parsed = parse_world(bus.pack(world.message()))  # exactly as the bridge reads it
        m = parsed.map
        self.contract.insert(
            keys.MAP,
            {
                "map_id": m.map_id,
                "resolution_m": m.resolution,
                "origin_x": m.origin_x,
                "origin_y": m.origin_y,
                "origin_yaw": m.origin_yaw,
                "width": m.width,
                "height": m.height,
                "grid": m.grid,
                "source": m.source,
                "loaded_at": "monolith",  # the planner's map version: never changes here
            },
        )
        for r in parsed.robots:
            self.contract.insert(keys.ROBOT, {**vars(r), "world": parsed.name})
        for s in parsed.stations:
            self.contract.insert(keys.CHARGING_STATION, {**vars(s), "map_id": parsed.name})
        for strategy in strategies:
            row = {
                "code": strategy.code,
                "planner_scenario": strategy.planner_scenario,
                "controller_scenarios": list(strategy.controller_scenarios),
                "params": dict(strategy.params),
            }
            self.contract.insert(keys.STRATEGY, row)

    def set_strategy(self, robot_id: str, code: str) -> None:
        """What the strategy service writes for an accepted ``SET_STRATEGY``."""
        row = {"robot_id": robot_id, "strategy_code": code, "resume_code": None, "source": "user"}
        self.contract.insert(keys.ACTIVE_STRATEGY, row)

    def set_goal(self, robot_id: str, x: float, y: float) -> int:
        """What ``pnav.commands.set_goal`` writes (no earlier goal to supersede here)."""
        row = {"robot_id": robot_id, "x": x, "y": y, "tolerance_m": GOAL_TOLERANCE_M}
        row |= {"status": "active", "stamp": self.now, "finished_stamp": None}
        return self.contract.insert(keys.GOAL, row)

    # -- running ------------------------------------------------------------------------------
    def _sink(self, robot_id: str, topic: str, message: dict[str, Any]) -> None:
        self._readings.append((robot_id, topic, message, time.perf_counter()))

    def _notify(self, table: str, robot: str | None, _row_id: int | None) -> None:
        """A change notification: wake the engines that watch the table (their services
        subscribe to exactly those), and let the planner note it as its observer does."""
        for engine, tables in self._watching:
            if table in tables:
                engine.wake()
        self.planner_state.note(keys.notify_key(table, robot), b"")

    def step(self) -> None:
        self.sim.step()
        self.now = now = self.sim.time
        self.decision_service.runtime.clock.update(now, 0.0)  # rate 0: exactly ``now``
        readings, self._readings = self._readings, []
        for robot_id, topic, message, produced in readings:
            self.bridge.ingest(robot_id, topic, message, produced)
            self.on_message(robot_id, topic, message)
        self.bridge.tick(now)
        for _ in range(MAX_PASSES):
            for engine in self.engines:
                if engine.due(now):
                    engine.activate(now)
            self.bridge.relay(now)
            if not any(e.woken or e.hurried for e in self.engines):
                return
        raise AdapterError(f"the engines were still due after {MAX_PASSES} passes at {now} s")

    def close(self) -> None:
        self.sim.close()

"""The navigation stack in one process: sim, bridge, controller, planner, decision.

What each part is made of (docs/MONOLITH.md has the whole list): every scenario service's
own store (caches, what notifications told it) and rules, seeded by the service's own seeding
code, on the in-memory source of pnav/monolith/memory_<svc>.py instead of the SQL one:

- controller: ``pnav.monolith.memory_controller.controller_engine``, the meta-controller and its
  scenarios on a ``ControllerStore``;
- planner: ``pnav.monolith.memory_planner.planner_engine``, the meta-planner and its rules on a
  ``PlannerStore`` whose gates count sim time;
- decision: ``pnav.monolith.memory_decision.decision_engine``, the meta-decision and issue rules on
  a ``DecisionStore``;
- bridge: pnav/monolith/memory_bridge.py; the strategy service is not run: the episode's strategy is
  written to ``active_strategy`` once, as ``SET_STRATEGY`` would, and no system command is
  acted on (none arises in a navigation episode: the battery starts full).

One :meth:`MonolithStack.step`: the sim senses and advances one physics step; its readings
become rows; every row written is announced to the stores whose service watches its table
(``note``, as ``ScenarioService.on_notification``) and wakes their engines; then every engine
that is due (a notification for a table it watches, a ``hurry``, or F = 50 ms of sim time
since its last start) runs an activation, controller, planner, decision in that order, on
the monolith's own event loop, and the bridge sends what was decided, until nothing more is
due. The command reaches the sim before its next physics step.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, Protocol

import uvloop

from common import bus
from common.bus import Notification
from common.contract import keys, records
from pnav.monolith.contract import AdapterError, MemoryContract
from pnav.monolith.engines import SteppedEngine
from pnav.monolith.memory_bridge import Applied, Bridge
from pnav.monolith.memory_controller import controller_engine
from pnav.monolith.memory_decision import decision_engine
from pnav.monolith.memory_planner import planner_engine
from services.bridge.world_message import parse_world
from services.sim.sim import SimConfig, Simulation
from services.sim.world_spec import World

GOAL_TOLERANCE_M = 0.15  # pnav.cli.stack_commands.set_goal's default, and the goal table's
MAX_PASSES = 50  # engine passes in one step before the loop is deemed to spin


class Store(Protocol):
    """What every service's store does with a change notification."""

    def note(self, note: Notification) -> None: ...


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
        self._seqs: dict[tuple[str, str | None], int] = {}  # a notification's seq, per key
        self.contract = MemoryContract()
        self.on_message = on_message
        self._readings: list[tuple[str, str, dict[str, Any], float]] = []
        self._loop = uvloop.new_event_loop()

        def sim_now() -> float:
            return self.now

        self.controller = SteppedEngine("controller", sim_now)
        self.controller_store = controller_engine(self.contract, self.controller, sim_now)
        # the planner's own gates (re-reads, replanning, battery checks) count sim time
        # here, as they do in a lockstep run of the stack: deterministic runs
        self.planner = SteppedEngine("planner", sim_now)
        self.planner_store = planner_engine(self.contract, self.planner, sim_now)
        self.decision = SteppedEngine("decision", sim_now)
        self.decision_store = decision_engine(self.contract, self.decision, sim_now)
        self.engines = (self.controller, self.planner, self.decision)
        # what each service subscribes to: the tables its meta rules watch
        stores: tuple[Store, ...] = (self.controller_store, self.planner_store, self.decision_store)
        self._watching = [
            (engine, store, frozenset(engine.watched_tables))
            for engine, store in zip(self.engines, stores, strict=True)
        ]
        self.contract.row_listeners.append(self._notify)

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
        """What ``pnav.cli.stack_commands.set_goal`` writes (no earlier goal to supersede here)."""
        row = {"robot_id": robot_id, "x": x, "y": y, "tolerance_m": GOAL_TOLERANCE_M}
        row |= {"status": "active", "stamp": self.now, "finished_stamp": None}
        return self.contract.insert(keys.GOAL, row)

    # -- running ------------------------------------------------------------------------------
    def _sink(self, robot_id: str, topic: str, message: dict[str, Any]) -> None:
        self._readings.append((robot_id, topic, message, time.perf_counter()))

    def _notify(
        self, table: str, robot: str | None, row_id: int | None, row: dict[str, Any] | None
    ) -> None:
        """A change notification: what ``ScenarioService.watch`` does for each service that
        watches ``table``: tell its store, then wake its engine for ``robot``. It carries the
        row's image (numbered: one publisher, no gap), as a writer's notification does in the
        stack."""
        seq = self._seqs[(table, robot)] = self._seqs.get((table, robot), 0) + 1
        note = Notification(table, robot, row_id, row, "monolith", seq)
        for engine, store, tables in self._watching:
            if table in tables:
                store.note(note)
                engine.wake(robot)
            elif table in getattr(store, "listens", ()):
                store.note(note)  # ScenarioService.listens: kept, no wake-up

    def step(self) -> None:
        self.sim.step()
        self.now = now = self.sim.time
        readings, self._readings = self._readings, []
        for robot_id, topic, message, produced in readings:
            self.bridge.ingest(robot_id, topic, message, produced)
            self.on_message(robot_id, topic, message)
        self.bridge.tick(now)
        self._loop.run_until_complete(self._settle(now))

    async def _settle(self, now: float) -> None:
        """Activations until no engine is due (each in the order the stack's would start)."""
        for _ in range(MAX_PASSES):
            for engine in self.engines:
                if engine.due(now):
                    await engine.activate(now)
            self.bridge.relay(now)
            if not any(e.signals.pending for e in self.engines):
                return
        raise AdapterError(f"the engines were still due after {MAX_PASSES} passes at {now} s")

    def close(self) -> None:
        self.sim.close()
        self._loop.close()

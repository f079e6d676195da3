"""The controller as the monolith runs it: the real store over the in-memory contract, the
meta-controller seeded on a real Engine, every contract change told to the store. Tests
write rows as the bridge and the strategy service would and run activations one by one."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from common.bus import Notification
from common.contract import keys
from common.contract.records import Robot, Strategy
from common.controller_core.scenario import Key, installed_scenarios
from common.engine import Engine
from pnav.monolith.contract import MemoryContract
from pnav.monolith.memory_controller import MemoryControllerSource
from services.controller.meta import ControllerState, Scenarios, seed_controller
from services.controller.store import ControllerStore
from tests.unit.controller.scans import BURGER, Obstacle, scan

SIM_NOW = 10.0


class Rig:
    """``tick()`` runs one activation and returns the sources that recommended during it."""

    def __init__(
        self,
        scenarios: Scenarios | None = None,
        source: Callable[[MemoryContract], MemoryControllerSource] = MemoryControllerSource,
        *,
        images: bool = False,
    ) -> None:
        self.contract = MemoryContract()
        self.now: float | None = SIM_NOW  # sim time the rules see (None: no clock yet)
        self.wall = 0.0  # the store's clock: the caches' recheck counts it
        self.source = source(self.contract)
        self.owned: set[str] | None = None  # None: this replica owns every robot
        self.store = ControllerStore(
            self.source, lambda: self.wall, lambda: self.now, serves=self.owns
        )
        self.engine = Engine()
        # as the service and the monolith: an activation's recommendations written at its end
        self.engine.at_activation_end(self.store.defer_recommendations())
        self.state: ControllerState = seed_controller(
            self.engine,
            self.store,
            installed_scenarios() if scenarios is None else scenarios,
            owns=self.owns,
        )
        # images: every notification carries its row, numbered per key as a Notifier does
        self.images = images
        self.seqs: dict[tuple[str, str | None], int] = {}
        self.contract.row_listeners.append(self._notify)
        self.add_robot(BURGER)

    def owns(self, robot_id: str) -> bool:
        return self.owned is None or robot_id in self.owned

    def _notify(
        self, table: str, robot: str | None, row_id: int | None, row: dict[str, Any] | None
    ) -> None:
        if not self.images:
            self.store.note(Notification(table, robot, row_id))
            return
        seq = self.seqs[(table, robot)] = self.seqs.get((table, robot), 0) + 1
        self.store.note(Notification(table, robot, row_id, row, "rig", seq))

    # -- rows, as the other services write them -------------------------------------------
    def add_robot(self, robot: Robot) -> None:
        self.contract.insert(keys.ROBOT, {**vars(robot), "world": "test"})

    def remove_robot(self, robot_id: str) -> None:
        """A DELETE FROM robot (the in-memory contract has no deletes: the monolith never
        removes a robot), and its notification."""
        self.contract[keys.ROBOT]._by_robot.pop(robot_id)
        self.contract.changed(keys.ROBOT, robot_id, None)

    def set_strategy(self, robot_id: str, strategy: Strategy) -> None:
        """The strategy row (as written, or updated) and the robot's active_strategy row."""
        row: dict[str, Any] = {
            "code": strategy.code,
            "planner_scenario": strategy.planner_scenario,
            "controller_scenarios": list(strategy.controller_scenarios),
            "params": dict(strategy.params),
        }
        self.contract.insert(keys.STRATEGY, row)
        active = {"robot_id": robot_id, "strategy_code": strategy.code}
        self.contract.insert(keys.ACTIVE_STRATEGY, active | {"resume_code": None, "source": "user"})

    def new_scan(self, *obstacles: Obstacle, age_s: float = 0.0, robot_id: str = "r1") -> int:
        now = SIM_NOW if self.now is None else self.now
        sweep = scan(*obstacles, stamp=now - age_s)
        row = {k: v for k, v in vars(sweep).items() if k != "id"} | {"robot_id": robot_id}
        return self.contract.insert(keys.LASER_SCAN, row)

    def odometry(
        self,
        linear: float,
        angular: float = 0.0,
        stamp: float = SIM_NOW,
        robot_id: str = "r1",
        *,
        heard: bool = True,
    ) -> int:
        """An odometry row; ``heard=False``: its notification does not reach the store (the
        service hears no odometry by default: services/controller/store.py)."""
        row = {"robot_id": robot_id, "stamp": stamp, "x": 0.0, "y": 0.0, "yaw": 0.0}
        row |= {"linear_mps": linear, "angular_rps": angular}
        return self.contract.insert(keys.ODOMETRY, row, notify=heard)

    # -- running and looking ---------------------------------------------------------------
    async def tick(self) -> list[str]:
        before = len(self.recommendations())
        await self.engine.activation()
        return [r["source"] for r in self.recommendations()[before:]]

    def recommendations(self) -> list[dict[str, Any]]:
        """Every command_recommendation row, in id order (as written)."""
        rows = self.contract[keys.COMMAND_RECOMMENDATION].all_rows()
        return sorted(rows, key=lambda row: int(row["id"]))

    def running(self) -> list[Key]:
        return sorted(self.state.supervisor.running)

    def queued(self) -> list[str]:
        """The rules waiting for the next activation, by name."""
        return sorted(type(rule).__name__ for rule in self.engine.current)

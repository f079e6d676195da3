"""The planner as the service seeds it, on the in-memory contract and the real store, driven
one engine activation at a time on a sim clock the test moves (no database, no Zenoh)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from common.bus import Notification
from common.config import EngineSettings
from common.contract import keys
from common.engine import Engine
from common.planner_core.scenario import MoveScenario
from pnav.monolith.contract import MemoryContract
from pnav.monolith.memory_planner import MemoryPlannerSource
from pnav.monolith.strategies import shipped_strategies
from services.planner import meta
from services.planner.store import PlannerStore
from services.planner.target import TargetRule

ROBOT = "r1"


class Planner:
    """One robot standing at (0, 0) facing +x, its odometry and battery written every tick."""

    def __init__(
        self,
        scenarios: Mapping[str, type[MoveScenario]] | None = None,
        extra_strategies: tuple[dict[str, Any], ...] = (),
    ) -> None:
        self.t = 100.0
        self.pose = (0.0, 0.0)  # where sense() says the robot is
        self.yaw = 0.0  # ...its heading
        self.rates = (0.0, 0.0)  # ...and its measured linear and angular velocity
        self.contract = MemoryContract()
        self.store = PlannerStore(MemoryPlannerSource(self.contract), self.now, self.now)
        self.contract.listeners.append(
            lambda table, robot, row_id: self.store.note(Notification(table, robot, row_id))
        )
        self.engine = Engine(EngineSettings(period_s=60.0), name="planner")
        self.engine.clock = self.now
        # as the service and the monolith: an activation's recommendations written at its end
        self.engine.at_activation_end(self.store.defer_recommendations())
        self.owned = {ROBOT}
        found = meta.move_scenarios() if scenarios is None else scenarios
        self.rules = meta.seed(self.engine, self.store, found, owns=self.owned.__contains__)
        for strategy in shipped_strategies().values():
            row = {
                "code": strategy.code,
                "planner_scenario": strategy.planner_scenario,
                "controller_scenarios": list(strategy.controller_scenarios),
                "params": dict(strategy.params),
            }
            self.contract.insert(keys.STRATEGY, row)
        for row in extra_strategies:
            self.contract.insert(keys.STRATEGY, {"controller_scenarios": [], **row})
        self.contract.insert(
            keys.ROBOT,
            {
                "robot_id": ROBOT,
                "world": None,
                "max_linear_mps": 0.22,
                "max_angular_rps": 2.84,
                "footprint_radius_m": 0.105,
            },
        )
        self.contract.insert(
            keys.CHARGING_STATION,
            {"station_id": "dock", "map_id": None, "x": -2.0, "y": 0.0, "radius_m": 0.3},
        )

    def now(self) -> float:
        return self.t

    # -- what the other parties write --------------------------------------------------------
    def strategy(self, code: str) -> None:
        row = {"robot_id": ROBOT, "strategy_code": code, "resume_code": None, "source": "user"}
        self.contract.insert(keys.ACTIVE_STRATEGY, row)

    def goal(
        self,
        x: float,
        y: float,
        yaw: float | None = None,
        yaw_tolerance_rad: float | None = None,
        waypoints: tuple[dict[str, Any], ...] = (),
    ) -> int:
        """A goal (with a heading, and a route's waypoints: dicts of goal_waypoint columns,
        x and y at least), written as people.set_goal writes it: waypoints first, one
        notification each."""
        row = {"robot_id": ROBOT, "x": x, "y": y, "tolerance_m": 0.15, "status": "active"}
        row |= {"yaw": yaw, "yaw_tolerance_rad": yaw_tolerance_rad}
        row |= {"stamp": self.t, "finished_stamp": None}
        goal_id = self.contract.insert(keys.GOAL, row, notify=False)
        for seq, w in enumerate(waypoints, start=1):
            wp = {"tolerance_m": 0.3, "yaw": None, "yaw_tolerance_rad": None, "stop": False}
            wp |= {"status": "pending", "reason": None, "reached_stamp": None}
            wp |= {"robot_id": ROBOT, "goal_id": goal_id, "seq": seq, **w}
            self.contract.insert(keys.GOAL_WAYPOINT, wp, notify=False)
        if waypoints:
            self.contract.changed(keys.GOAL_WAYPOINT, ROBOT, goal_id)
        self.contract.changed(keys.GOAL, ROBOT, goal_id, row)
        return goal_id

    def waypoint_rows(self, goal_id: int) -> list[tuple[int, str, float | None]]:
        """(seq, status, reached_stamp) of the goal's waypoints."""
        rows = self.contract[keys.GOAL_WAYPOINT].rows(ROBOT)
        return [
            (w["seq"], w["status"], w["reached_stamp"]) for w in rows if w["goal_id"] == goal_id
        ]

    async def tick(self, dt: float = 0.05) -> None:
        """Sim time moves on, a sensor row of each kind comes, the engine runs once."""
        self.sense(dt)
        await self.engine.activation()

    def sense(self, dt: float) -> None:
        """Sim time moves on; the robot's odometry and battery rows come."""
        self.t += dt
        x, y = self.pose
        odometry = {"robot_id": ROBOT, "stamp": self.t, "x": x, "y": y, "yaw": self.yaw}
        linear, angular = self.rates
        self.contract.insert(
            keys.ODOMETRY, odometry | {"linear_mps": linear, "angular_rps": angular}
        )
        battery = {"robot_id": ROBOT, "stamp": self.t, "energy_wh": 15.0, "capacity_wh": 19.98}
        self.contract.insert(keys.BATTERY, battery | {"percentage": 75.0, "charging": False})

    def map(self, occupied: np.ndarray, resolution: float, origin: tuple[float, float]) -> None:
        """The robot's map (the only one): ``occupied`` rows from the bottom, as the table."""
        h, w = occupied.shape
        row = {"map_id": "test", "resolution_m": resolution, "origin_yaw": 0.0}
        row |= {"origin_x": origin[0], "origin_y": origin[1], "width": w, "height": h}
        grid = np.where(occupied, 100, 0).astype(np.uint8).tobytes()
        self.contract.insert(keys.MAP, row | {"grid": grid, "source": "test", "loaded_at": "1"})

    def scan(self, ranges: np.ndarray) -> None:
        """A laser scan now, beams from -pi at 2 pi / len(ranges) apart."""
        row = {"robot_id": ROBOT, "stamp": self.t, "angle_min": -np.pi, "range_min": 0.12}
        row |= {"angle_increment": 2 * np.pi / len(ranges), "range_max": 3.5}
        self.contract.insert(keys.LASER_SCAN, row | {"ranges": ranges.tolist()})

    def goal_row(self, goal_id: int) -> dict[str, Any]:
        return dict(self.contract[keys.GOAL].by_id[goal_id])

    # -- what the test looks at --------------------------------------------------------------
    def running(self) -> dict[str, tuple[str, str]]:
        """kind -> (rule, strategy) of the robot's live rules."""
        return {
            kind: (rule.spec.rule.__name__, rule.spec.strategy)
            for (_robot, kind), rule in self.rules.supervisor.running.items()
        }

    def queue(self) -> list[str]:
        """The rules the next activation runs, in order."""
        return [rule.name for rule in self.engine.current]

    def live_rule(self, kind: str) -> TargetRule:
        rule = self.rules.supervisor.rule((ROBOT, kind))
        assert isinstance(rule, TargetRule)
        return rule

    def recommendations(self, source: str | None = None) -> list[dict[str, Any]]:
        rows = self.contract[keys.COMMAND_RECOMMENDATION].rows(ROBOT)
        return [r for r in rows if source is None or r["source"] == source]

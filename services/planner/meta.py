"""The meta-planner: per robot, exactly one planner scenario, the one its strategy names.

A continuous rule (it clones itself). Each activation it refreshes the shared state (the
active strategies; robots, maps and chargers when they changed) and, per robot, makes sure
the right target rules are alive (for the robots this replica owns, docs/REPLICAS.md):

- "move": the strategy's ``planner_scenario`` (``turn_then_move`` or ``move_while_turning``),
  none for a strategy without one (IDLE). An unknown name is logged once and ignored.
- "battery": ``BatteryCheck`` when the strategy drives to the goal, ``ChargeComplete`` when
  it drives to the nearest charger.

Each kind has one slot per robot holding a token. A target rule clones itself only while
the slot still holds its token, so a strategy change ends the old rule (its generation step
sees the new token) and starts the new one in the same activation, with no overlap. A
target rule stamps the slot every time it runs; one that stopped (an error discards a rule
for good) is replaced after STALE_ROUNDS activations.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Callable, Iterable

from common import log
from common.contract import keys
from common.engine import Rule
from services.planner.battery import BatteryCheck, ChargeComplete
from services.planner.move_while_turning import MoveWhileTurning
from services.planner.scenario import MoveScenario
from services.planner.state import PlannerState, RobotState, Slot
from services.planner.turn_then_move import TurnThenMove

logger = logging.getLogger("pnav.planner")

SCENARIOS: dict[str, type[MoveScenario]] = {
    TurnThenMove.scenario: TurnThenMove,
    MoveWhileTurning.scenario: MoveWhileTurning,
}
TARGETS = ("goal", "nearest_charger")
STALE_ROUNDS = 20

TargetRule = type[MoveScenario] | type[BatteryCheck] | type[ChargeComplete]


class MetaPlanner(Rule):
    scenario = "meta_planner"
    meta = True
    watches = (
        keys.ACTIVE_STRATEGY,
        keys.STRATEGY,
        keys.GOAL,
        keys.ODOMETRY,
        keys.BATTERY,
        keys.MAP,
        keys.ROBOT,
        keys.CHARGING_STATION,
    )

    _tokens = itertools.count(1)

    def __init__(
        self, state: PlannerState, owns: Callable[[str], bool] = lambda _robot_id: True
    ) -> None:
        self.state = state
        self.owns = owns  # replicas: plan only for the robots this one owns
        self.spawned: list[Rule] = []

    async def data_acquisition(self) -> None:
        await self.state.refresh()

    def actions(self) -> None:
        self.state.meta_round += 1
        self.spawned = []
        for robot in self.state.robots.values():
            if not self.owns(robot.info.robot_id):
                # Another replica's robot: end its rules here (docs/REPLICAS.md).
                self.keep(robot, "move", None)
                self.keep(robot, "battery", None)
                continue
            move, battery = self.wanted(robot)
            self.keep(robot, "move", move)
            self.keep(robot, "battery", battery)
            strategy = robot.strategy
            if strategy is None or strategy.params.get("target") != "nearest_charger":
                robot.station = None  # the next CHARGE session chooses its charger afresh

    def wanted(self, robot: RobotState) -> tuple[type[MoveScenario] | None, TargetRule | None]:
        strategy = robot.strategy
        if strategy is None or strategy.planner_scenario is None:
            return None, None
        move = SCENARIOS.get(strategy.planner_scenario)
        if move is None:
            self.state.warn_once(
                f"scenario-{strategy.planner_scenario}",
                "unknown planner scenario: ignored",
                scenario=strategy.planner_scenario,
                strategy=strategy.code,
            )
            return None, None
        target = strategy.params.get("target")
        if target not in TARGETS:
            self.state.warn_once(
                f"target-{strategy.code}-{target}",
                "strategy has no known target param: no planner",
                strategy=strategy.code,
                target=str(target),
            )
            return None, None
        return move, BatteryCheck if target == "goal" else ChargeComplete

    def keep(self, robot: RobotState, kind: str, rule: TargetRule | None) -> None:
        robot_id = robot.info.robot_id
        if rule is None or robot.strategy is None:
            if robot.slots.pop(kind, None) is not None:
                log.event(logger, logging.INFO, "planner rule ended", robot=robot_id, kind=kind)
            return
        spec = (rule.__name__, robot.strategy.code)
        slot = robot.slots.get(kind)
        if slot is not None and slot.spec == spec:
            if self.state.meta_round - slot.beat <= STALE_ROUNDS:
                return
            log.event(
                logger,
                logging.WARNING,
                "planner rule stopped; replaced",
                robot=robot_id,
                rule=rule.__name__,
            )
        token = next(self._tokens)
        robot.slots[kind] = Slot(spec, token, self.state.meta_round)
        self.spawned.append(rule(self.state, robot_id, token))
        log.event(
            logger,
            logging.INFO,
            "planner rule started",
            robot=robot_id,
            rule=rule.scenario,
            strategy=robot.strategy.code,
        )

    def rule_generation(self) -> Iterable[Rule]:
        spawned, self.spawned = self.spawned, []
        return [*spawned, self.clone()]

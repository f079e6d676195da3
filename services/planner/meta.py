"""The meta-planner: per robot, exactly one planner scenario, the one its strategy names.

A continuous rule (it clones itself). Each activation it refreshes the store (the active
strategies; robots, maps and chargers when they changed) and says which target rules it
wants alive, per robot this replica owns (docs/REPLICAS.md):

- (robot, "move"): the strategy's ``planner_scenario``, one of the move scenarios found at
  start under the ``pnav.planner.scenarios`` entry points (``turn_then_move``,
  ``move_while_turning``, or a plug-in's: docs/PLANNER.md); none for a strategy without one
  (IDLE). A strategy this stack cannot run (a planner scenario not installed here, or
  controller scenarios no live controller offers: scenario_offer) gets ``Unrunnable``
  instead, which fails the robot's goals with the reason (unrunnable.py).
- (robot, "battery"): ``BatteryCheck`` when the strategy drives to the goal,
  ``ChargeComplete`` when it drives to the nearest charger.

A ``common.engine.Supervisor`` does the rest: a rule no longer wanted (IDLE, a robot gone
or owned by another replica) is terminated and leaves the queue after its next run; a
changed spec (another scenario, or another strategy) ends the old rule and starts the new
one in the same activation, with no overlap; a rule the engine discarded after an error is
started again at the next run of the meta-planner.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Mapping

from common import log
from common.contract import keys, offers, records
from common.engine import Engine, Rule, Supervisor
from common.planner_core.scenario import SCENARIO_GROUP, MoveScenario
from common.plugins import load_scenarios
from services.planner.battery_rules import BatteryCheck, ChargeComplete
from services.planner.recovery_rule import Recovery
from services.planner.scenario import MoveRule, move_rule
from services.planner.target import RuleKey, Spec, TargetRule
from services.planner.unrunnable import Unrunnable
from services.planner.view import PlannerStoreView, PlannerView
from services.planner.world_model import RobotState

logger = logging.getLogger("pnav.planner")

# The planner's own scenarios, listed first (the thesis' order); plug-ins follow by name.
SHIPPED = ("turn_then_move", "move_while_turning")
TARGETS = ("goal", "nearest_charger")
MOVE, BATTERY, RECOVERY = "move", "battery", "recovery"


def move_scenarios() -> dict[str, type[MoveScenario]]:
    """The move scenarios installed now: scenario name -> class (the shipped ones first)."""
    # MoveScenario is abstract (``select``): here it is only what a plug-in must subclass
    found = load_scenarios(SCENARIO_GROUP, MoveScenario)  # type: ignore[type-abstract]
    rank = {name: i for i, name in enumerate(SHIPPED)}
    order = sorted(found, key=lambda name: (rank.get(name, len(SHIPPED)), name))
    return {name: found[name] for name in order}


def recovers(params: Mapping[str, object]) -> bool:
    """Whether a strategy driving to the goal asks for the recovery rule (recovery.py)."""
    return params.get("recovery") is True


class PlannerRules:
    """The target rules the planner keeps alive, and the move scenarios it can start.

    Held outside the meta rule so that a meta rule re-seeded after an error takes over the
    rules already running instead of starting them twice.
    """

    def __init__(self, view: PlannerView, scenarios: Mapping[str, type[MoveScenario]]) -> None:
        self.view = view
        # each scenario as the rule that runs it (scenario.move_rule)
        self.scenarios: dict[str, type[MoveRule]] = {
            name: move_rule(cls) for name, cls in scenarios.items()
        }
        # any change of spec starts a fresh rule: a new strategy never inherits a route
        # follower's or a battery rule's memory
        self.supervisor: Supervisor[RuleKey, Spec] = Supervisor(
            "planner", self._start, restart_on=lambda _old, _new: True
        )

    def _start(self, key: RuleKey, spec: Spec) -> TargetRule:
        robot_id, _kind = key
        log.event(
            logger,
            logging.INFO,
            "planner rule started",
            robot=robot_id,
            rule=spec.rule.scenario,
            strategy=spec.strategy,
        )
        return spec.rule(self.view, key, spec)

    def running(self, robot_id: str) -> list[str]:
        """The kinds of rule running for the robot ("move", "battery")."""
        return [kind for rid, kind in self.supervisor.running if rid == robot_id]

    def forget(self, robot_ids: Iterable[str]) -> None:
        """End these robots' rules now (ownership changed: the next meta run starts afresh
        those this replica still owns)."""
        robots = set(robot_ids)
        self.supervisor.end_all(k for k in self.supervisor.running if k[0] in robots)


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
        keys.ZONE,
    )

    def __init__(
        self,
        store: PlannerStoreView,
        rules: PlannerRules | None = None,
        owns: Callable[[str], bool] = lambda _robot_id: True,
    ) -> None:
        self.store = store
        # without ``rules`` (a meta-planner of its own, in a test), the installed scenarios
        self.rules = rules if rules is not None else PlannerRules(store, move_scenarios())
        self.owns = owns  # replicas: plan only for the robots this one owns
        self.spawned: list[Rule] = []

    async def data_acquisition(self) -> None:
        await self.store.refresh()

    def actions(self) -> None:
        wanted: dict[RuleKey, Spec] = {}
        for robot in self.store.robots():
            robot_id = robot.info.robot_id
            if not self.owns(robot_id):
                continue  # another replica's robot: its rules end here (docs/REPLICAS.md)
            strategy = robot.strategy
            why = None if strategy is None else self.unrunnable(strategy)
            if strategy is not None and why is not None:
                # nothing would drive it: its goals fail with the reason (unrunnable.py)
                wanted[(robot_id, MOVE)] = Spec(Unrunnable, strategy.code, why)
                robot.station = None
                continue
            move, battery = self.wanted(robot)
            for kind, rule in ((MOVE, move), (BATTERY, battery)):
                if rule is not None and strategy is not None:
                    wanted[(robot_id, kind)] = Spec(rule, strategy.code)
            if battery is BatteryCheck and strategy is not None and recovers(strategy.params):
                wanted[(robot_id, RECOVERY)] = Spec(Recovery, strategy.code)
            if strategy is None or strategy.params.get("target") != "nearest_charger":
                robot.station = None  # the next CHARGE session chooses its charger afresh
        self.spawned = self.rules.supervisor.reconcile(wanted)

    def unrunnable(self, strategy: records.Strategy) -> str | None:
        """Why ``strategy`` cannot run (None: it can): it names a planner scenario this
        planner does not have, or controller scenarios no live controller offers."""
        name = strategy.planner_scenario
        if name is not None and name not in self.rules.scenarios:
            self.store.warn_once(
                f"scenario-{name}",
                "unknown planner scenario: the goals of its robots fail",
                scenario=name,
                strategy=strategy.code,
            )
            return (
                f"strategy {strategy.code} names planner scenario {name!r} that this planner "
                f"cannot run; it runs: {', '.join(self.rules.scenarios) or 'none'}"
            )
        return offers.unoffered(
            strategy.code, offers.CONTROLLER, strategy.controller_scenarios, self.store.offers()
        )

    def wanted(self, robot: RobotState) -> tuple[type[TargetRule] | None, type[TargetRule] | None]:
        """The robot's move and battery rules under its strategy (None: none)."""
        strategy = robot.strategy
        if strategy is None or strategy.planner_scenario is None:
            return None, None
        move = self.rules.scenarios.get(strategy.planner_scenario)
        if move is None:
            return None, None
        target = strategy.params.get("target")
        if target not in TARGETS:
            self.store.warn_once(
                f"target-{strategy.code}-{target}",
                "strategy has no known target param: no planner",
                strategy=strategy.code,
                target=str(target),
            )
            return None, None
        return move, BatteryCheck if target == "goal" else ChargeComplete

    def rule_generation(self) -> Iterable[Rule]:
        spawned, self.spawned = self.spawned, []
        return [*spawned, self.clone()]


def seed(
    engine: Engine,
    store: PlannerStoreView,
    scenarios: Mapping[str, type[MoveScenario]],
    owns: Callable[[str], bool] = lambda _robot_id: True,
) -> PlannerRules:
    """Seed the meta-planner on ``engine``, as the service does; the rules it keeps."""
    rules = PlannerRules(store, scenarios)
    engine.add_meta(lambda: MetaPlanner(store, rules, owns))
    return rules

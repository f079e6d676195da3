"""The meta-decision rule: arbitrate every robot's live recommendations.

A continuous rule (it clones itself), woken by every command_recommendation notification
and, as a fallback, every period F (which also drives the 0.1 s re-issue). Each activation:

1. the live recommendations (``expires_stamp`` > sim now) of the robots this replica owns
   that are due a look (:meth:`DecisionView.live`: their recommendations changed, or their
   re-issue is due; every robot after the store read the table): the store keeps them from
   the rows' images and reads the table only as its fallback;
2. per robot, :func:`decide_robot` and :func:`decide_system` say what is due;
3. target rules are created for what is to be written: one :class:`IssueRobotCommand` with
   the velocity commands of every robot decided (one statement, one commit for all of
   them), one :class:`IssueSystemCommand` per system command; the engine is hurried for each
   robot decided so they run in the very next activation rather than F later.

The target rules sit ahead of this rule's clone in the queue, so the next look at the table
already sees what they wrote (``treated_by``, the last command issued): nothing is decided
twice.

The rule sees the contract only through :class:`~services.decision.view.DecisionView`, and
the engine only through ``hurry``, a plain callable: scheduling is the engine's business, not
the store's, and a callable is the smallest thing that lets the rule ask for it (the service
passes ``engine.hurry``, the monolith its own engine's, a test whatever it observes).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

from common.contract import keys
from common.contract.recommendations import Recommendation
from common.engine import Engine, Rule
from services.decision.arbitration import (
    RobotDecision,
    decide_robot,
    decide_system,
)
from services.decision.scenario import IssueRobotCommand, IssueSystemCommand
from services.decision.view import DecisionView


class MetaDecision(Rule):
    scenario = "decision"
    meta = True
    watches = (keys.COMMAND_RECOMMENDATION, keys.ROBOT)

    def __init__(self, store: DecisionView, hurry: Callable[[str], None]) -> None:
        self.store = store
        self.hurry = hurry
        self.clock_started = False
        self.now = 0.0
        self.live: dict[str, list[Recommendation]] = {}
        self.targets: list[Rule] = []

    async def data_acquisition(self) -> None:
        self.targets = []
        self.live = {}
        # Expiry is in sim time: with no clock yet, "live" means nothing. Wait for the sim.
        now = self.store.sim_now()
        self.clock_started = now is not None
        if now is None:
            return
        self.now = now
        self.live = await self.store.live(now)

    def activation_guards(self) -> bool:
        return self.clock_started

    def actions(self) -> None:
        commands: list[RobotDecision] = []
        systems: list[Rule] = []
        for robot_id in sorted(self.live):
            recs = self.live[robot_id]
            robot_recs = [r for r in recs if r.kind == "robot"]
            system_recs = [r for r in recs if r.kind == "system"]
            command = decide_robot(robot_id, robot_recs, self.store.issued(robot_id), self.now)
            if command is not None:
                commands.append(command)
            system = decide_system(robot_id, system_recs, self.now)
            if system is not None:
                systems.append(IssueSystemCommand(self.store, system))
            if command is not None or system is not None:
                self.hurry(robot_id)
        if commands:  # every robot's command in one write (one statement, one commit)
            self.targets.append(IssueRobotCommand(self.store, commands))
        self.targets += systems

    def rule_generation(self) -> Iterable[Rule]:
        return [*self.targets, self.clone()]


def seed(engine: Engine, store: DecisionView) -> None:
    """Add the decision's meta rule to ``engine`` (the service and the monolith both)."""
    engine.add_meta(lambda: MetaDecision(store, engine.hurry))

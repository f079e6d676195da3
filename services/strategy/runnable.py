"""Whether a strategy can run now: every scenario it names is offered by a live planner or
controller (scenario_offer, common.contract.offers). A pure function of what the command's
snapshot read, kept apart from the decision table (commands.py) it feeds.

The strategy service never imports the planner or the controller: it learns what they can
run from the rows they publish. A family none of whose instances has a live offer (starting,
stopped, or one that publishes none) is not judged: the planner fails the goal of a robot
whose strategy it cannot run once it is up (docs/PLANNER.md).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from common.contract.offers import CONTROLLER, PLANNER, Offers, unoffered


@dataclass(frozen=True)
class Needs:
    """The scenarios a strategy row names."""

    planner: str | None
    controller: tuple[str, ...]


def refusal(code: str, needs: Mapping[str, Needs], offers: Offers) -> str | None:
    """Why strategy ``code`` cannot run now, or None (it can, or cannot be judged):
    ``strategy X names controller scenario 'foo' that no running controller offers;
    offered: a, b, c``."""
    need = needs.get(code)
    if need is None:
        return None
    planner = (need.planner,) if need.planner is not None else ()
    return unoffered(code, PLANNER, planner, offers) or unoffered(
        code, CONTROLLER, need.controller, offers
    )

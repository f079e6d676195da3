"""The planner while people hold strategy locked and every goal row (CONTRACT.md, *Roles*:
"Locks"): its engine runs on, and it plans for a new goal once the locks are gone."""

from __future__ import annotations

import asyncio

from common.contract import keys
from common.contract.grants import role_name
from common.contract.roles import role_url
from pnav.bench.faults import tablelock
from services.planner.service import PlannerService
from tests.contract.planner.conftest import World

HOLD_S = 5.0


async def test_the_planner_runs_on_under_a_goal_lock_and_plans_once_it_is_gone(
    db_url: str, world: World, planner: PlannerService
) -> None:
    await world.strategy("GOTO_AVOID")
    first = await world.goal(0.0, 2.0)
    await world.next_recommendation(lambda r: r["inputs"].get("goal") == first, within=30)
    engine = planner.engine
    async with tablelock.held(role_url(db_url, role_name("user"), None)):
        before = engine.counters.activations
        for _ in range(int(HOLD_S / 0.5)):
            # a hint that strategy changed, as its writers send: the planner reads it again
            world.db.notifier.notify(keys.STRATEGY, None, None)
            await asyncio.sleep(0.5)
        # without a lock timeout the activation under way waits for the lock till it goes
        assert engine.counters.activations - before >= 5
    after = await world.newest_id()
    second = await world.goal(2.0, 0.0)
    rec = await world.next_recommendation(
        lambda r: r["inputs"].get("goal") == second, after=after, within=30
    )
    assert rec["linear_mps"] > 0.1 or rec["angular_rps"] != 0

"""The planner against Postgres and Zenoh: a robot whose strategy names a controller scenario
no live controller offers (a controller restarted without its plug-in) has its goal failed
with the reason, not left ``active``."""

from __future__ import annotations

from common.contract import keys
from pnav._testing import eventually
from services.planner.service import PlannerService
from tests.contract.planner.conftest import World


async def test_a_goal_under_a_strategy_no_live_controller_can_run_fails_with_the_reason(
    world: World, planner: PlannerService
) -> None:
    await world.db.pool.execute(
        "INSERT INTO strategy (code, planner_scenario, controller_scenarios, params) VALUES "
        "('WARP', 'turn_then_move', '{warp_drive,safety_stop}', "
        '\'{"target": "goal", "planner_drives": false}\')'
    )
    await world.strategy("WARP")
    first = await world.goal(2.0, 0.0)
    # no controller has published offers: nothing to judge by, the goal is planned for
    await eventually(
        lambda: world.db.pool.fetchval(
            "SELECT count(*) FROM planned_path WHERE goal_id = $1", first
        ),
        what="a path planned for the goal",
    )
    assert await world.db.pool.fetchval("SELECT status FROM goal WHERE id = $1", first) == "active"

    # the controller comes back without the plug-in
    await world.execute(
        keys.SCENARIO_OFFER,
        None,
        "INSERT INTO scenario_offer (service, instance, scenario) VALUES "
        "('controller', 'c-1', 'dwa'), ('controller', 'c-1', 'safety_stop')",
    )
    row = await eventually(
        lambda: world.db.pool.fetchrow(
            "SELECT status, reason FROM goal WHERE id = $1 AND status <> 'active'", first
        ),
        what="the goal marked failed",
    )
    assert (row["status"], row["reason"]) == (
        "failed",
        "strategy WARP names controller scenario 'warp_drive' that no running controller "
        "offers; offered: dwa, safety_stop",
    )
    path = await world.db.pool.fetchrow(
        "SELECT target, cardinality(xs) AS points FROM planned_path ORDER BY id DESC LIMIT 1"
    )
    assert (path["target"], path["points"]) == ("none", 0)  # the local controller stops

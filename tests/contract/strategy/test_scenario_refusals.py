"""A switch to a strategy naming a scenario no live planner or controller offers
(scenario_offer) is rejected with the reason on the command's row, and the robot's strategy
stays; a strategy that names such a scenario can still be INSERTed (offers change), and a
family with no live offer is not judged."""

from __future__ import annotations

import asyncpg

from common.config import ServiceConfig
from common.contract import keys
from common.runtime import Runtime
from pnav._testing import ClockPlayer, running_service
from services.strategy.service import StrategyService
from tests.contract.strategy.test_strategy_service import (
    active,
    add_robot,
    default_applied,
    system_command,
    treated,
    user_command,
)

CONTROLLERS = ("avoid_left", "avoid_right", "dwa", "safety_stop")
PLANNERS = ("turn_then_move", "move_while_turning")


async def offer(client: Runtime, family: str, names: tuple[str, ...], instance: str) -> None:
    """What a running planner or controller publishes at its start."""
    await client.database.write(
        keys.SCENARIO_OFFER,
        None,
        "INSERT INTO scenario_offer (service, instance, scenario) "
        "SELECT $1, $2, unnest($3::text[])",
        family,
        instance,
        list(names),
    )


async def add_strategy(
    client: Runtime, code: str, planner: str, controllers: tuple[str, ...]
) -> None:
    # people write strategies: a strategy naming a scenario nobody offers is still accepted
    await client.database.write(
        keys.STRATEGY,
        None,
        "INSERT INTO strategy (code, planner_scenario, controller_scenarios, params) "
        'VALUES ($1, $2, $3::text[], \'{"target": "goal"}\')',
        code,
        planner,
        list(controllers),
    )


async def test_a_strategy_naming_a_scenario_no_running_service_offers_is_refused(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig
) -> None:
    await add_robot(client, "r1")
    await offer(client, "planner", PLANNERS, "planner-1")
    await offer(client, "controller", CONTROLLERS, "controller-1")
    await add_strategy(client, "WARP", "turn_then_move", ("warp_drive", "safety_stop"))
    await add_strategy(client, "ODD", "no_such_planner", ("safety_stop",))
    async with running_service(StrategyService, service_config):
        await default_applied(client, "r1")

        warp = await user_command(client, "r1", "SET_STRATEGY", "WARP")
        row = await treated(client, keys.USER_COMMAND, warp)
        assert (row["status"], row["reason"]) == (
            "rejected",
            "strategy WARP names controller scenario 'warp_drive' that no running controller "
            "offers; offered: avoid_left, avoid_right, dwa, safety_stop",
        )
        odd = await user_command(client, "r1", "SET_STRATEGY", "odd")
        row = await treated(client, keys.USER_COMMAND, odd)
        assert (row["status"], row["reason"]) == (
            "rejected",
            "strategy ODD names planner scenario 'no_such_planner' that no running planner "
            "offers; offered: move_while_turning, turn_then_move",
        )
        now = await active(client, "r1")
        assert now is not None and (now["strategy_code"], now["source"]) == (
            "GOTO_AVOID",
            "default",
        )

        # a strategy every scenario of which is offered switches as before
        fast = await user_command(client, "r1", "SET_STRATEGY", "GOTO_FAST")
        row = await treated(client, keys.USER_COMMAND, fast)
        assert (row["status"], row["reason"]) == ("accepted", "GOTO_AVOID -> GOTO_FAST")

        # once a controller with the plug-in runs, WARP switches
        await offer(client, "controller", ("warp_drive", "safety_stop"), "controller-2")
        warp = await user_command(client, "r1", "SET_STRATEGY", "WARP")
        row = await treated(client, keys.USER_COMMAND, warp)
        assert (row["status"], row["reason"]) == ("accepted", "GOTO_FAST -> WARP")


async def test_a_battery_save_to_a_charge_strategy_no_controller_can_run_is_refused(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig
) -> None:
    await add_robot(client, "r1")
    await offer(client, "controller", ("dwa", "safety_stop"), "controller-1")
    async with running_service(StrategyService, service_config):
        await default_applied(client, "r1")
        save = await system_command(client, "r1", "CMD_BATTSAVE")
        row = await treated(client, keys.SYSTEM_COMMAND, save)
        assert (row["status"], row["status_reason"]) == (
            "rejected",
            "strategy CHARGE names controller scenarios 'avoid_left', 'avoid_right' that no "
            "running controller offers; offered: dwa, safety_stop",
        )
        now = await active(client, "r1")
        assert now is not None and now["strategy_code"] == "GOTO_AVOID"


async def test_offers_of_instances_that_stopped_refreshing_are_not_counted(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig, db_url: str
) -> None:
    await add_robot(client, "r1")
    await offer(client, "controller", ("safety_stop",), "controller-1")
    await add_strategy(client, "WARP", "turn_then_move", ("warp_drive", "safety_stop"))
    async with running_service(StrategyService, service_config):
        await default_applied(client, "r1")
        refused = await user_command(client, "r1", "SET_STRATEGY", "WARP")
        assert (await treated(client, keys.USER_COMMAND, refused))["status"] == "rejected"

        # the only controller died a minute ago: no live controller, nothing to judge by
        conn = await asyncpg.connect(db_url)
        try:
            await conn.execute("UPDATE scenario_offer SET updated_at = now() - interval '1 min'")
        finally:
            await conn.close()
        accepted = await user_command(client, "r1", "SET_STRATEGY", "WARP")
        row = await treated(client, keys.USER_COMMAND, accepted)
        assert (row["status"], row["reason"]) == ("accepted", "GOTO_AVOID -> WARP")

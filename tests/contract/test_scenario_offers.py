"""The planner and the controller publish the scenarios they can run in scenario_offer
(migration 12) while they run, refresh them, and withdraw them at a clean stop; each family
writes only its own rows (CONTRACT.md, *scenario_offer*)."""

from __future__ import annotations

from datetime import datetime

import asyncpg
import pytest

from common.config import EngineSettings, ServiceConfig, ZenohSettings
from common.contract import offers
from common.controller_core.scenario import installed_scenarios
from common.service import ScenarioService
from pnav._testing import as_service_role, eventually, running_service
from services.controller.service import ControllerService
from services.planner.meta import move_scenarios
from services.planner.service import PlannerService

OFFERS_SQL = "SELECT instance, scenario, updated_at FROM scenario_offer WHERE service = $1"


def _offered(family: str) -> set[str]:
    found = move_scenarios() if family == "planner" else installed_scenarios()
    return set(found)


@pytest.mark.parametrize(
    ("family", "service_cls"), [("planner", PlannerService), ("controller", ControllerService)]
)
async def test_a_running_service_offers_its_scenarios_refreshes_them_and_withdraws_them(
    db_url: str, zenoh_settings: ZenohSettings, family: str, service_cls: type[ScenarioService]
) -> None:
    config = ServiceConfig(
        service=family,
        database_url=await as_service_role(db_url, family),  # exactly its grants
        zenoh=zenoh_settings,
        engine=EngineSettings(period_s=0.05),
        stats_period_s=5.0,
        instance=f"{family}-offers",
    )
    conn = await asyncpg.connect(db_url)
    try:
        # a dead instance of the family: its stale rows go when the next one publishes
        await conn.execute(
            "INSERT INTO scenario_offer (service, instance, scenario, updated_at) "
            "VALUES ($1, 'gone-1', 'old_plugin', now() - interval '1 hour')",
            family,
        )
        async with running_service(service_cls, config):

            async def published() -> list[asyncpg.Record]:
                return list(await conn.fetch(OFFERS_SQL, family))

            rows = await eventually(published, what=f"the {family}'s offers")
            assert {r["instance"] for r in rows} == {f"{family}-offers"}
            assert {r["scenario"] for r in rows} == _offered(family)
            assert {"turn_then_move", "safety_stop"} & {r["scenario"] for r in rows}
            first: datetime = min(r["updated_at"] for r in rows)

            async def refreshed() -> bool:
                return all(r["updated_at"] > first for r in await published())

            await eventually(refreshed, within=4 * offers.OFFER_REFRESH_S, what="a refresh")
            live = await offers.live_offers(conn)
            assert live.offered(family) == frozenset(_offered(family))
        assert await conn.fetch(OFFERS_SQL, family) == []  # withdrawn at its clean stop
    finally:
        await conn.close()


async def test_a_family_cannot_offer_or_withdraw_for_another(db_url: str) -> None:
    conn = await asyncpg.connect(await as_service_role(db_url, "planner"))
    admin = await asyncpg.connect(db_url)
    try:
        await conn.execute(
            "INSERT INTO scenario_offer (service, instance, scenario) VALUES "
            "('planner', 'p-1', 'turn_then_move')"
        )
        with pytest.raises(asyncpg.InsufficientPrivilegeError, match="row-level security"):
            await conn.execute(
                "INSERT INTO scenario_offer (service, instance, scenario) VALUES "
                "('controller', 'p-1', 'safety_stop')"
            )
        await admin.execute(
            "INSERT INTO scenario_offer (service, instance, scenario) VALUES "
            "('controller', 'c-1', 'safety_stop')"
        )
        assert await conn.execute("DELETE FROM scenario_offer WHERE service = 'controller'") == (
            "DELETE 0"
        )
        assert await admin.fetchval("SELECT count(*) FROM scenario_offer") == 2
    finally:
        await conn.close()
        await admin.close()

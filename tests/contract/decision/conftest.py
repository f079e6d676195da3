"""Fixtures for the decision service's contract tests (client and clock: ../conftest.py)."""

from __future__ import annotations

import pytest

from common.config import EngineSettings, ServiceConfig, ZenohSettings
from pnav._testing import as_service_role


@pytest.fixture
async def service_config(db_url: str, zenoh_settings: ZenohSettings) -> ServiceConfig:
    """The service as its own Postgres role: the tests prove it needs no other grant."""
    return ServiceConfig(
        service="decision",
        database_url=await as_service_role(db_url, "decision"),
        zenoh=zenoh_settings,
        engine=EngineSettings(period_s=0.05),
        stats_period_s=5.0,
        instance="decision-test",
    )

"""Fixtures for the strategy service's contract tests (client and clock: ../conftest.py)."""

from __future__ import annotations

import pytest

from common.config import EngineSettings, ServiceConfig, ZenohSettings


@pytest.fixture
def service_config(db_url: str, zenoh_settings: ZenohSettings) -> ServiceConfig:
    return ServiceConfig(
        service="strategy",
        database_url=db_url,
        zenoh=zenoh_settings,
        engine=EngineSettings(period_s=0.05),
        stats_period_s=5.0,
        instance="strategy-test",
    )

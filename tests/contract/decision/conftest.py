"""Fixtures for the decision service's contract tests: a foreign client and the sim clock.

The client plays everyone else: it writes rows with plain SQL and publishes the change
notifications a writer must publish, and it plays the sim's clock.
"""

from __future__ import annotations

from collections.abc import AsyncIterator

import pytest

from common.config import EngineSettings, ServiceConfig, ZenohSettings
from common.runtime import Runtime
from common.testing import ClockPlayer


@pytest.fixture
async def client(db_url: str, zenoh_settings: ZenohSettings) -> AsyncIterator[Runtime]:
    runtime = await Runtime.open(
        ServiceConfig(
            service="tester", database_url=db_url, zenoh=zenoh_settings, instance="tester-1"
        )
    )
    try:
        yield runtime
    finally:
        await runtime.close()


@pytest.fixture
async def clock(client: Runtime) -> AsyncIterator[ClockPlayer]:
    player = ClockPlayer(client.zenoh, stamp=10.0)
    player.start()
    try:
        yield player
    finally:
        await player.stop()


@pytest.fixture
def service_config(db_url: str, zenoh_settings: ZenohSettings) -> ServiceConfig:
    return ServiceConfig(
        service="decision",
        database_url=db_url,
        zenoh=zenoh_settings,
        engine=EngineSettings(period_s=0.05),
        stats_period_s=5.0,
        instance="decision-test",
    )

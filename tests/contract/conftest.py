"""Fixtures shared by the contract tests: a foreign client and the sim clock.

The client plays everyone else around the service under test: it writes rows with plain SQL
and publishes the change notifications a writer must publish, and it plays the sim's clock.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Iterable, Sequence

import pytest

from common.config import ServiceConfig, ZenohSettings
from common.runtime import Runtime
from common.service import ScenarioService
from pnav._testing import ClockPlayer, eventually

CLOCK_START = 10.0


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
    """Sim time held at CLOCK_START until a test moves it (``clock.stamp = ...``)."""
    player = ClockPlayer(client.zenoh, stamp=CLOCK_START)
    player.start()
    try:
        yield player
    finally:
        await player.stop()


async def split_between(
    replicas: Sequence[ScenarioService], robots: Iterable[str], within: float = 20.0
) -> list[frozenset[str]]:
    """Wait until ``replicas`` own disjoint shares, every one non-empty, that cover
    ``robots``; return the shares (docs/REPLICAS.md)."""
    wanted = set(robots)

    def split() -> list[frozenset[str]] | None:
        shares = [replica.owned_robots() for replica in replicas]
        if any(not share for share in shares):
            return None
        owned = [share for share in shares if share is not None]
        if sum(len(share) for share in owned) != len(wanted) or set().union(*owned) != wanted:
            return None
        return owned

    shares: list[frozenset[str]] = await eventually(
        split, within=within, what="the replicas to split the robots"
    )
    return shares

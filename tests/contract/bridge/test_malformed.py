"""Malformed sensor messages on every key: counted, logged, dropped; the bridge carries on."""

from __future__ import annotations

import logging
from collections import Counter

import asyncpg
import pytest
from hypothesis import HealthCheck, given, settings

from common.contract import keys
from pnav._testing import eventually
from services.bridge import sensor_payloads as messages
from tests.contract.bridge.conftest import (
    BridgeFactory,
    FakeSim,
    bridge_with_world,
    count,
)
from tests.unit.bridge import payloads
from tests.unit.bridge.payloads import Bad, bad_messages

pytestmark = pytest.mark.timeout(90)

SENSOR_TABLES = (keys.ODOMETRY, keys.LASER_SCAN, keys.BATTERY, keys.COLLISION_EVENT)


def generate(n: int) -> list[Bad]:
    """``n`` malformed samples of every kind, drawn by hypothesis."""
    drawn: list[Bad] = []

    @settings(
        max_examples=n,
        database=None,
        deadline=None,
        suppress_health_check=list(HealthCheck),
    )
    @given(bad_messages("r1"))
    def collect(bad: Bad) -> None:
        drawn.append(bad)

    collect()
    return drawn


async def test_malformed_messages_never_reach_the_database_nor_stop_the_bridge(
    start_bridge: BridgeFactory,
    sim: FakeSim,
    conn: asyncpg.Connection,
    caplog: pytest.LogCaptureFixture,
) -> None:
    bridge = await bridge_with_world(start_bridge, sim, payloads.world())
    flood = generate(300)
    expected = Counter(bad.reason for bad in flood if bad.reason is not None)
    # every kind of fault is in the flood, on every sensor topic
    assert set(expected) >= set(messages.REASONS) - {messages.TOO_LARGE}
    assert {bad.topic for bad in flood} == set(keys.SENSOR_TOPICS)
    big = Bad(keys.SCAN, "r1", payloads.pack(payloads.scan(pad="x" * 70_000)), "too_large")
    flood.append(big)
    expected["too_large"] += 1

    with caplog.at_level(logging.WARNING, logger="pnav.bridge"):
        for bad in flood:
            sim.put(bad.key, bad.payload)
        await eventually(
            lambda: bridge.counters.malformed_total() == len(flood),
            what=f"{len(flood)} refusals",
            within=20,
        )

    got: Counter[str] = Counter()
    for (_, reason), n in bridge.counters.malformed.items():
        got[reason] += n
    for reason, n in expected.items():
        assert got[reason] >= n, reason  # random bytes add to some reason or other
    assert sum(bridge.counters.messages_in.values()) == len(flood)
    for topic in keys.SENSOR_TOPICS:
        sent = sum(1 for bad in flood if bad.topic == topic)
        assert bridge.counters.malformed_total(topic) == sent
    for table in SENSOR_TABLES:
        assert await count(conn, table) == 0, table
    assert sum(bridge.counters.rows_written.values()) == 0
    # the log is rate-limited: at most one line per (topic, reason) in this short flood
    lines = [r for r in caplog.records if r.getMessage() == "malformed message dropped"]
    assert 0 < len(lines) <= len(bridge.counters.malformed)

    # still alive: a valid message is written as usual
    sim.sensor("r1", keys.ODOM, payloads.odom(seq=99))
    await eventually(lambda: bridge.counters.rows_written[keys.ODOMETRY] == 1, what="the row")
    assert await conn.fetchval("SELECT seq FROM odometry") == 99

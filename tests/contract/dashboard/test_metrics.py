"""GET /metrics against the contract alone: rows written and notified by a foreign client,
leases taken with the contract's SQL functions, a real supervisor restarting a real process.

The exposition is parsed with prometheus-client's own parser; every family docs/METRICS.md
lists is there, and the values move with what the stack does.
"""

from __future__ import annotations

import asyncio
import re
import sys
from collections.abc import AsyncIterator
from pathlib import Path

import asyncpg
import httpx
import pytest
from prometheus_client.parser import text_string_to_metric_families
from starlette.applications import Starlette

from common import bus
from common.contract import keys
from common.runtime import Runtime
from pnav._testing import eventually
from pnav.run.process_supervisor import ProcessSpec, Supervisor
from pnav.run.supervisor_report import SupervisorReport
from services.dashboard.stack_metrics import Metrics, MetricsConfig

pytestmark = pytest.mark.timeout(60)

DOC = Path(__file__).resolve().parents[3] / "docs" / "METRICS.md"
Samples = dict[tuple[str, tuple[tuple[str, str], ...]], float]


@pytest.fixture
async def metrics(client: Runtime) -> AsyncIterator[Metrics]:
    """Metrics as the dashboard runs it: started on a pool and the Zenoh session, fed every
    change notification."""
    m = Metrics(MetricsConfig(refresh_s=0.1, rate_window_s=10.0))
    await m.start(client.database.pool, client.zenoh)
    sub = bus.subscribe(
        client.zenoh,
        keys.NOTIFY_ALL,
        lambda key, payload: m.note(bus.Notification.decode(key, payload)),
    )
    try:
        yield m
    finally:
        sub.undeclare()
        await m.close()


async def scrape(m: Metrics) -> tuple[set[str], Samples]:
    app = Starlette(routes=m.routes())
    transport = httpx.ASGITransport(app=app)
    async with httpx.AsyncClient(transport=transport, base_url="http://dash") as http:
        response = await http.get("/metrics")
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/plain; version=0.0.4")
    families = list(text_string_to_metric_families(response.text))
    samples: Samples = {}
    for family in families:
        for s in family.samples:
            samples[(s.name, tuple(sorted(s.labels.items())))] = s.value
    return {f.name for f in families}, samples


def value(samples: Samples, name: str, **labels: str) -> float | None:
    return samples.get((name, tuple(sorted(labels.items()))))


def documented_families() -> set[str]:
    """Family names in docs/METRICS.md's tables (a counter's without ``_total``)."""
    names = set(re.findall(r"^\| `(pnav_[a-z0-9_]+)`", DOC.read_text(), re.M))
    return {n.removesuffix("_total") for n in names}


async def add_robot(conn: asyncpg.Connection, robot: str) -> None:
    await conn.execute("INSERT INTO robot (robot_id, world) VALUES ($1, 'test')", robot)


async def test_metrics_parse_and_name_every_documented_family(
    metrics: Metrics, client: Runtime
) -> None:
    names, samples = await scrape(metrics)
    documented = documented_families()
    assert len(documented) >= 15
    # families with no sample yet (no engine, no lease...) are still announced
    assert documented <= names, f"missing from /metrics: {sorted(documented - names)}"
    assert {n for n in names if n.startswith("pnav_")} <= documented, "undocumented metric"
    assert value(samples, "pnav_robots") == 0


async def test_rows_and_notifications_per_table_move(metrics: Metrics, client: Runtime) -> None:
    db = client.database
    async with db.pool.acquire() as conn:
        await add_robot(conn, "r1")
        for n in range(3):
            ids = [
                await conn.fetchval(
                    "INSERT INTO odometry (robot_id, stamp, seq, x, y, yaw, linear_mps, "
                    "angular_rps) VALUES ('r1', $1, $2, 0, 0, 0, 0, 0) RETURNING id",
                    float(n * 2 + k),
                    n * 2 + k,
                )
                for k in range(2)
            ]
            # one notification for a burst of two rows, as the bridge sends them
            db.notifier.notify(keys.ODOMETRY, "r1", ids[-1])

    async def three_notified() -> Samples | None:
        _, samples = await scrape(metrics)
        seen = value(samples, "pnav_notifications_total", table="odometry")
        return samples if seen == 3 else None

    samples = await eventually(three_notified, what="three odometry notifications")
    # three notifications, each naming the newest of two rows: six rows, counted from the
    # table's newest id when the metrics started
    assert value(samples, "pnav_table_rows_total", table="odometry") == 6
    per_s = value(samples, "pnav_table_rows_per_second", table="odometry")
    assert per_s is not None and per_s > 0


async def test_sense_to_act_is_sampled_once_per_recommendation(
    metrics: Metrics, client: Runtime
) -> None:
    db = client.database
    async with db.pool.acquire() as conn:
        await add_robot(conn, "r1")
        scan = await conn.fetchval(
            "INSERT INTO laser_scan (robot_id, stamp, angle_min, angle_increment, range_min, "
            "range_max, ranges) VALUES ('r1', 1.0, 0, 0.1, 0.12, 3.5, '{1.0}') RETURNING id"
        )
        await asyncio.sleep(0.02)  # the recommender's work: 20 ms between the inserts
        rec = await conn.fetchval(
            "INSERT INTO command_recommendation (robot_id, kind, source, priority, linear_mps, "
            "angular_rps, stamp, expires_stamp, inputs) VALUES ('r1', 'robot', 'avoid_left', "
            "50, 0.1, 0.5, 1.0, 1.5, $1::jsonb) RETURNING id",
            {"laser_scan": scan, "scan_stamp": 1.0},  # the pool encodes jsonb (common.db)
        )
        for _ in range(3):  # the decision and two re-issues of it
            await conn.execute(
                "INSERT INTO command2robot (robot_id, stamp, linear_mps, angular_rps, "
                "recommendation_id, source) VALUES ('r1', 1.0, 0.1, 0.5, $1, 'avoid_left')",
                rec,
            )

    async def sampled() -> Samples | None:
        _, samples = await scrape(metrics)
        count = value(samples, "pnav_sense_to_act_seconds_count", robot="r1", origin="laser_scan")
        return samples if count else None

    samples = await eventually(sampled, what="a sense-to-act sample")
    await asyncio.sleep(0.3)  # three more refreshes: the re-issues add nothing
    _, samples = await scrape(metrics)
    labels = {"robot": "r1", "origin": "laser_scan"}
    assert value(samples, "pnav_sense_to_act_seconds_count", **labels) == 1
    total = value(samples, "pnav_sense_to_act_seconds_sum", **labels)
    assert total is not None and 0.02 <= total < 5.0
    assert value(samples, "pnav_sense_to_act_seconds_bucket", **labels, le="0.01") == 0
    stage = value(samples, "pnav_sense_to_act_stage_seconds_sum", stage="row_to_recommendation")
    assert stage is not None and 0.02 <= stage <= total


async def test_engine_stats_and_lease_ownership(metrics: Metrics, client: Runtime) -> None:
    pool = client.database.pool
    await pool.execute(
        "INSERT INTO engine_stats (service, instance, rule_type, scenario, executed, "
        "activated, acted, errors, total_time_s, max_time_s) VALUES "
        "('controller', 'controller-1', 'AvoidLeft', 'avoid_left', 120, 40, 39, 1, 0.5, 0.01)"
    )
    await pool.execute("INSERT INTO robot (robot_id, world) VALUES ('r1', 'test')")
    holder = await asyncpg.connect(client.config.database_url)  # a replica's lock connection
    try:
        acquired = await holder.fetchval(
            "SELECT robot_lease_acquire('controller', 'r1', 'controller-7')"
        )
        assert acquired is not None
        owner = {"service": "controller", "robot": "r1", "instance": "controller-7"}
        engine = {
            "service": "controller",
            "instance": "controller-1",
            "scenario": "avoid_left",
            "rule": "AvoidLeft",
        }

        async def seen() -> Samples | None:
            _, samples = await scrape(metrics)
            return samples if value(samples, "pnav_lease_owner", **owner) == 1 else None

        samples = await eventually(seen, what="the lease owner")
        assert value(samples, "pnav_engine_rules_executed_total", **engine) == 120
        assert value(samples, "pnav_engine_rules_acted_total", **engine) == 39
        assert value(samples, "pnav_engine_rule_errors_total", **engine) == 1
        assert value(samples, "pnav_robots") == 1
        await pool.execute(
            "UPDATE engine_stats SET executed = 180, updated_at = now() "
            "WHERE instance = 'controller-1'"
        )
        await holder.fetchval("SELECT robot_lease_release('controller', 'r1', 'shutdown')")

        async def moved() -> bool:
            _, samples = await scrape(metrics)
            return (
                value(samples, "pnav_engine_rules_executed_total", **engine) == 180
                and value(samples, "pnav_lease_owner", **owner) is None
            )

        await eventually(moved, what="new engine stats, the lease given back")
    finally:
        await holder.close()


async def test_supervisor_restarts_are_counted(
    metrics: Metrics, client: Runtime, tmp_path: Path
) -> None:
    crashing = ProcessSpec("crasher", [sys.executable, "-c", "import sys; sys.exit(3)"])
    supervisor = Supervisor([crashing], tmp_path / "logs")
    report = SupervisorReport(supervisor, client.zenoh, period_s=0.2)
    stop = asyncio.Event()
    await supervisor.start()
    report.start()
    watcher = asyncio.create_task(supervisor.watch(stop))
    try:

        async def restarted_twice() -> bool:
            _, samples = await scrape(metrics)
            count = value(samples, "pnav_supervisor_restarts_total", process="crasher")
            return count is not None and count >= 2

        await eventually(restarted_twice, within=20, what="two restarts counted")
        assert supervisor.status()["crasher"]["last_exit"] == 3
    finally:
        stop.set()
        await watcher
        await report.close()
        await supervisor.stop()

"""A 10 s Postgres outage costs each service a bounded handful of log lines: one when it
went, a summary now and then while it lasts, one when it is back (common/outage.py), and
the bridge's own warnings folded the same way."""

from __future__ import annotations

import re
import time
from collections.abc import Iterator
from pathlib import Path

import asyncpg
import pytest

from common.config import ServiceConfig
from common.postmaster import kill_postmaster
from common.runtime import Runtime
from pnav._testing import eventually
from pnav.cli import stack_commands
from pnav.run.embedded_postgres import EmbeddedPostgres
from pnav.run.launcher import launched
from pnav.run.stack_options import StackOptions

pytestmark = pytest.mark.timeout(240)

OUTAGE_S = 10.0
_RECORD = re.compile(r"^\d{4}-\d\d-\d\dT")  # a log record's first line (not a traceback's)
# Per process over the outage and its end. The bridge: the outage's own lines (went, a
# summary every 5 s, back), its watchdog's stop and its periodic counters. A scenario
# service has its events besides: leases lost and re-taken, each robot's scenarios ended
# and started again, a rule's first error and its summaries.
MAX_RECORDS = {"bridge": 12, "sim": 4}
MAX_SERVICE_RECORDS = 22


@pytest.fixture
def own_postgres(monkeypatch: pytest.MonkeyPatch) -> Iterator[EmbeddedPostgres]:
    """A server of the test's own, that the launcher does not look after: it stays down for
    as long as the test wants."""
    server = EmbeddedPostgres()
    server.start()
    monkeypatch.setenv("PNAV_DATABASE_URL", server.dsn())
    try:
        yield server
    finally:
        server.stop()


async def newest_command(url: str) -> int:
    try:
        conn = await asyncpg.connect(url, timeout=2)
    except (OSError, asyncpg.PostgresError, TimeoutError):
        return -1
    try:
        return int(await conn.fetchval("SELECT coalesce(max(id), 0) FROM command2robot"))
    finally:
        await conn.close()


def lines(log_dir: Path) -> dict[str, list[str]]:
    return {p.stem: p.read_text().splitlines() for p in sorted(log_dir.glob("*.log"))}


async def test_a_ten_second_postgres_outage_costs_each_service_a_handful_of_lines(
    own_postgres: EmbeddedPostgres, tmp_path: Path
) -> None:
    url = own_postgres.dsn()
    options = StackOptions(world="open_room", rate="1", robots=1, zenoh_port=None)
    options.log_dir = tmp_path / "logs"
    async with launched(options) as stack:
        rt = await Runtime.open(
            ServiceConfig(service="e2e", database_url=url, zenoh=stack.local.zenoh)
        )
        try:
            assert await stack_commands.robot_ids(rt, wait_s=60) == ["r1"]
            await stack_commands.set_goal(rt, "r1", 4.0, 4.0)
        finally:
            await rt.close()
        await eventually(lambda: _grew(url, 0), 60, what="a first command2robot row")
        before = lines(options.log_dir)

        kill_postmaster(own_postgres.data_dir)
        assert await newest_command(url) == -1
        time.sleep(OUTAGE_S)  # noqa: ASYNC251 - the whole stack is in other processes
        own_postgres.restart()
        back_at = await newest_command(url)
        await eventually(lambda: _grew(url, back_at), 60, what="command2robot rows after it")
        after = lines(options.log_dir)
    counts = {}
    for service, text in after.items():
        new = text[len(before.get(service, [])) :]
        records = [line for line in new if _RECORD.match(line)]
        counts[service] = (len(records), len(new))
        print(f"--- {service}: {len(records)} records, {len(new)} lines\n" + "\n".join(new))
    assert {"bridge", "strategy", "planner", "controller", "decision"} <= set(counts)
    for service, (records, raw) in counts.items():
        assert records <= MAX_RECORDS.get(service, MAX_SERVICE_RECORDS), (service, records)
        assert raw == records, service  # no traceback: a lost connection is one line


async def _grew(url: str, than: int) -> bool:
    return await newest_command(url) > than

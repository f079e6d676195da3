"""Shared fixtures: a real embedded Postgres and real Zenoh routers on loopback.

- ``pg``: one embedded Postgres per test session; ``contract_template`` is a database with
  every migration applied, so ``db_url`` (a fresh database per test) is a fast copy of it.
- ``zenoh_settings``: a fresh in-process Zenoh router on a free loopback port per test, with
  multicast scouting off; clients open sessions with these settings.
- Every async test runs under uvloop (``pytest_asyncio_loop_factories``).
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Iterator
from pathlib import Path

import asyncpg
import pytest
import uvloop

from common.config import ZenohSettings
from common.contract.migrate import apply_migrations
from pnav._testing import loopback_zenoh
from pnav.run.embedded_postgres import EmbeddedPostgres

TEMPLATE = "pnav_contract_template"


def pytest_asyncio_loop_factories(config: pytest.Config, item: pytest.Item) -> dict[str, object]:
    return {"uvloop": uvloop.new_event_loop}


@pytest.fixture(autouse=True)
def isolated_state(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A launcher started by a test writes its stack file in the test's own folder."""
    monkeypatch.setenv("PNAV_STATE_DIR", str(tmp_path / "state"))


@pytest.fixture(scope="session")
def pg() -> Iterator[EmbeddedPostgres]:
    server = EmbeddedPostgres()
    server.start()
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture(scope="session")
def contract_template(pg: EmbeddedPostgres) -> str:
    """Name of a database holding the whole contract, used as a template."""
    url = pg.create_database(TEMPLATE)

    async def migrate() -> None:
        conn = await asyncpg.connect(url)
        try:
            await apply_migrations(conn)
        finally:
            await conn.close()

    asyncio.run(migrate())
    return TEMPLATE


@pytest.fixture
def db_url(pg: EmbeddedPostgres, contract_template: str) -> str:
    """A fresh database with the contract applied, for one test."""
    return pg.create_database(template=contract_template)


@pytest.fixture
def empty_db_url(pg: EmbeddedPostgres) -> str:
    """A fresh, empty database (no contract), for migration tests."""
    return pg.create_database()


@pytest.fixture
async def conn(db_url: str) -> AsyncIterator[asyncpg.Connection]:
    from common.db import connect

    connection = await connect(db_url)
    try:
        yield connection
    finally:
        await connection.close()


@pytest.fixture
def zenoh_settings() -> Iterator[ZenohSettings]:
    with loopback_zenoh() as settings:
        yield settings

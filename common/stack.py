"""Local infrastructure for one machine: an embedded Postgres and an in-process Zenoh router.

``pnav`` commands use this to run with no server installed: Postgres comes from the
``pgserver`` package (a real server, started in a data directory), unless
``PNAV_DATABASE_URL`` names one; the router listens on loopback only.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path

import asyncpg
from zenoh import Session

from common.bus import start_router
from common.config import ZenohSettings
from common.contract.migrate import apply_migrations
from common.testing import EmbeddedPostgres, free_port


@dataclass
class LocalStack:
    database_url: str
    zenoh: ZenohSettings
    router: Session
    postgres: EmbeddedPostgres | None

    def env(self) -> dict[str, str]:
        """The variables a service process needs to join this stack."""
        return {"PNAV_DATABASE_URL": self.database_url, **self.zenoh.to_env()}


@contextlib.asynccontextmanager
async def local_stack(
    data_dir: Path | None = None, zenoh_port: int | None = None
) -> AsyncIterator[LocalStack]:
    """Start Postgres (embedded unless PNAV_DATABASE_URL is set) and a router; migrate."""
    postgres: EmbeddedPostgres | None = None
    url = os.environ.get("PNAV_DATABASE_URL", "").strip()
    if not url:
        postgres = EmbeddedPostgres(data_dir)
        postgres.start()
        url = postgres.dsn()
    endpoint = f"tcp/127.0.0.1:{zenoh_port or free_port()}"
    router = start_router((endpoint,))
    try:
        conn = await asyncpg.connect(url)
        try:
            await apply_migrations(conn)
        finally:
            await conn.close()
        yield LocalStack(url, ZenohSettings(mode="client", connect=(endpoint,)), router, postgres)
    finally:
        router.close()
        if postgres is not None:
            postgres.stop()

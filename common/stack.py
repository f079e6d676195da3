"""Local infrastructure for one machine: an embedded Postgres and an in-process Zenoh router.

``pnav`` commands use this to run with no server installed: Postgres comes from the
``pgserver`` package (a real server, started in a data directory), unless
``PNAV_DATABASE_URL`` names one; the router listens on loopback only. The embedded one is
looked after (common.postmaster): restarted on the same data directory if it dies, and
stopped (its temporary data directory removed) by a watcher if this process dies first.
A server named by ``PNAV_DATABASE_URL`` is not ours: neither is done to it.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path

import asyncpg
from zenoh import Session

from common.bus import start_router
from common.config import ZenohSettings
from common.contract.migrate import apply_migrations
from common.postmaster import Keeper, Lifeline, start_lifeline
from common.testing import EmbeddedPostgres, free_port


@dataclass
class LocalStack:
    database_url: str
    zenoh: ZenohSettings
    router: Session
    postgres: EmbeddedPostgres | None
    keeper: Keeper | None = None

    def env(self) -> dict[str, str]:
        """The variables a service process needs to join this stack."""
        return {"PNAV_DATABASE_URL": self.database_url, **self.zenoh.to_env()}


@contextlib.asynccontextmanager
async def local_stack(
    data_dir: Path | None = None, zenoh_port: int | None = None
) -> AsyncIterator[LocalStack]:
    """Start Postgres (embedded unless PNAV_DATABASE_URL is set) and a router; migrate."""
    postgres: EmbeddedPostgres | None = None
    lifeline: Lifeline | None = None
    keeper: Keeper | None = None
    url = os.environ.get("PNAV_DATABASE_URL", "").strip()
    if not url:
        # pgserver narrates every pg_ctl run at INFO; a restart would repeat all of it
        logging.getLogger("pgserver").setLevel(logging.WARNING)
        postgres = EmbeddedPostgres(data_dir)
        lifeline = start_lifeline(postgres.data_dir, temporary=postgres.temporary)
        try:
            postgres.start()
        except BaseException:
            postgres.stop()
            lifeline.close()
            raise
        url = postgres.dsn()
        keeper = Keeper(postgres)
    stop_keeper = asyncio.Event()
    keeping: asyncio.Task[None] | None = None
    try:
        endpoint = f"tcp/127.0.0.1:{zenoh_port or free_port()}"
        router = start_router((endpoint,))
        try:
            conn = await asyncpg.connect(url)
            try:
                await apply_migrations(conn)
            finally:
                await conn.close()
            if keeper is not None:
                keeping = asyncio.create_task(keeper.run(stop_keeper), name="postgres-keeper")
            zenoh = ZenohSettings(mode="client", connect=(endpoint,))
            yield LocalStack(url, zenoh, router, postgres, keeper)
        finally:
            stop_keeper.set()
            if keeping is not None:
                await keeping  # a restart under way ends before the server is stopped
            router.close()
    finally:
        if postgres is not None:
            postgres.stop()
        if lifeline is not None:
            lifeline.close()

"""Local infrastructure for one machine: an embedded Postgres and an in-process Zenoh router.

``pnav`` commands use this to run with no server installed: Postgres comes from the
``pgserver`` package (a real server, started in a data directory), unless
``PNAV_DATABASE_URL`` names one; the router listens on loopback only. The embedded one is
looked after (common.postmaster): restarted on the same data directory if it dies, and
stopped (its temporary data directory removed) by a watcher if this process dies first.
A server named by ``PNAV_DATABASE_URL`` is not ours: neither is done to it.

Zenoh between the local processes (:class:`LocalZenoh`, ``PNAV_LOCAL_ZENOH``): by default
each process is a *peer* that connects to the launcher's router and learns the other peers'
loopback endpoints from it (gossip scouting), then sends to them directly; the router stays
the rendezvous and the endpoint for clients (the CLI, a foreign service, the dashboard).
A message then crosses one TCP link instead of two and the launcher forwards none of it
(docs/BENCHMARKS.md, "Peer-to-peer Zenoh"). ``PNAV_LOCAL_ZENOH=client`` routes everything
through the router, as compose does (deploy/docker-compose.yml keeps the router).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
from collections.abc import AsyncIterator, Mapping
from dataclasses import dataclass
from pathlib import Path

import asyncpg
from zenoh import Session

from common.bus import start_router
from common.config import ZenohSettings
from common.contract.migrate import apply_migrations
from common.errors import ConfigError
from common.postmaster import Keeper, Lifeline, start_lifeline
from common.testing import EmbeddedPostgres, free_port

# Every local peer listens on loopback only, on a port of the kernel's choosing: the router
# tells the others where (gossip), so nothing needs a fixed port but the router.
PEER_LISTEN: tuple[str, ...] = ("tcp/127.0.0.1:0",)


@dataclass(frozen=True)
class LocalZenoh:
    """How the processes of a local stack reach each other over Zenoh."""

    # peer: directly, the router as rendezvous; client: every message through the router
    mode: str = "peer"

    def __post_init__(self) -> None:
        if self.mode not in ("peer", "client"):
            raise ConfigError(f"PNAV_LOCAL_ZENOH={self.mode!r} must be peer or client")

    @classmethod
    def from_env(cls, env: Mapping[str, str] | None = None) -> LocalZenoh:
        env = os.environ if env is None else env
        return cls(mode=env.get("PNAV_LOCAL_ZENOH", "").strip().lower() or cls.mode)

    def settings(self, router: str) -> ZenohSettings:
        """The Zenoh settings of a local process, given the router's endpoint."""
        if self.mode == "client":
            return ZenohSettings(mode="client", connect=(router,))
        return ZenohSettings(mode="peer", connect=(router,), listen=PEER_LISTEN, multicast=False)


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
    data_dir: Path | None = None,
    zenoh_port: int | None = None,
    local_zenoh: LocalZenoh | None = None,
) -> AsyncIterator[LocalStack]:
    """Start Postgres (embedded unless PNAV_DATABASE_URL is set) and a router; migrate.
    ``local_zenoh``: how the stack's processes use Zenoh (default: PNAV_LOCAL_ZENOH)."""
    local_zenoh = local_zenoh if local_zenoh is not None else LocalZenoh.from_env()
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
            zenoh = local_zenoh.settings(endpoint)
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

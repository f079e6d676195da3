"""What the benchmark runs the bridge against: an embedded Postgres with the contract, a
loopback Zenoh router, the world the sim would serve, and ``python -m services.bridge`` as a
separate process, as deployed."""

from __future__ import annotations

import asyncio
import os
import signal
import sys
import time
from types import TracebackType

import asyncpg
import zenoh

from common import bus
from common.config import ZenohSettings
from common.contract import keys
from common.contract.migrate import apply_migrations
from common.errors import ConnectionFailure
from pnav.bench.bridge.player import world
from pnav.run.embedded_postgres import EmbeddedPostgres, free_port

# the bridge must have written the world's robots within this long
READY_TIMEOUT_S = 30.0
# and exit within this long of SIGTERM
EXIT_TIMEOUT_S = 20.0


class BenchStack:
    """``async with BenchStack(robots) as stack``: Postgres, router and world up;
    :meth:`start_bridge` then starts the bridge. Everything stops on leaving."""

    def __init__(self, robots: list[str]) -> None:
        self.robots = robots
        self._pg = EmbeddedPostgres()
        self._router: zenoh.Session | None = None
        self._url = ""
        self._conn: asyncpg.Connection | None = None
        self._session: zenoh.Session | None = None
        self._queryable: zenoh.Queryable[None] | None = None
        self.child: asyncio.subprocess.Process | None = None
        self.settings = ZenohSettings()

    @property
    def conn(self) -> asyncpg.Connection:
        assert self._conn is not None, "use BenchStack in `async with`"
        return self._conn

    @property
    def session(self) -> zenoh.Session:
        assert self._session is not None, "use BenchStack in `async with`"
        return self._session

    async def __aenter__(self) -> BenchStack:
        try:
            await self._open()
        except BaseException:
            await self.close()
            raise
        return self

    async def __aexit__(
        self,
        _type: type[BaseException] | None,
        _exc: BaseException | None,
        _tb: TracebackType | None,
    ) -> None:
        await self.close()

    async def _open(self) -> None:
        self._pg.start()
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        self._router = bus.start_router((endpoint,))
        self.settings = ZenohSettings(mode="client", connect=(endpoint,))
        self._url = self._pg.create_database()
        self._conn = await asyncpg.connect(self._url)
        await apply_migrations(self._conn)
        # keep every row of the run: the seqs are read back afterwards
        await self._conn.execute("UPDATE retention_policy SET keep_rows_per_robot = 1000000")
        self._session = bus.open_session(self.settings)
        payload = bus.pack(world(self.robots))
        self._queryable = self._session.declare_queryable(
            keys.SIM_WORLD, lambda q: q.reply(keys.SIM_WORLD, payload)
        )

    async def start_bridge(self) -> float:
        """Start the bridge; the seconds until it had written the world's robots."""
        env = {**os.environ, "PNAV_DATABASE_URL": self._url, **self.settings.to_env()}
        env.setdefault("PNAV_LOG_LEVEL", "WARNING")
        self.child = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "services.bridge", env=env
        )
        started = time.monotonic()
        while await self.conn.fetchval("SELECT count(*) FROM robot") < len(self.robots):
            if time.monotonic() - started > READY_TIMEOUT_S:
                raise ConnectionFailure(
                    f"the bridge did not write the world in {READY_TIMEOUT_S:g} s"
                )
            await asyncio.sleep(0.05)
        return time.monotonic() - started

    @property
    def pid(self) -> int:
        """The bridge process's id."""
        assert self.child is not None, "start_bridge first"
        return self.child.pid

    async def stop_bridge(self) -> int:
        """SIGTERM the bridge, as a supervisor would; its exit code."""
        assert self.child is not None, "start_bridge first"
        self.child.send_signal(signal.SIGTERM)
        return await asyncio.wait_for(self.child.wait(), EXIT_TIMEOUT_S)

    async def close(self) -> None:
        if self.child is not None and self.child.returncode is None:
            self.child.kill()
            await self.child.wait()
        if self._queryable is not None:
            self._queryable.undeclare()
        if self._conn is not None:
            await self._conn.close()
        if self._session is not None:
            self._session.close()
        if self._router is not None:
            self._router.close()
        self._pg.stop()

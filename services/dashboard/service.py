"""The dashboard service: a web page of every robot, served over HTTP and a websocket.

Wiring (docs/DASHBOARD.md): a :class:`~services.dashboard.store.DashboardStore` on Postgres,
fed by every change notification (``pnav/db/**``), which it also hands to any extra
observers; a push loop that reads what the notifications marked and sends what changed to
the browsers every ``push_period_s``; and uvicorn serving :func:`create_app` inside this
process's event loop. It is a foreign client of the contract like the CLI: it writes only
the people's tables (goal, user_command, strategy), and imports no other service.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import sys
import time
from collections.abc import Callable, Generator, Sequence

import uvicorn
from starlette.routing import BaseRoute

from common import bus, log
from common.bus import Notification
from common.config import ServiceConfig
from common.contract import keys
from common.errors import ConnectionFailure
from common.runtime import Runtime, run_service
from services.dashboard.app import create_app
from services.dashboard.gate import AllowedHosts
from services.dashboard.hub import Hub
from services.dashboard.settings import DashboardSettings
from services.dashboard.stack_metrics import Metrics, MetricsConfig
from services.dashboard.store import DashboardStore, PgDashboardSource

SERVICE = "dashboard"
logger = logging.getLogger("pnav.dashboard")

Observer = Callable[[Notification], None]


class _Server(uvicorn.Server):
    """uvicorn, minus its own signal handling: the service's runtime owns SIGINT/SIGTERM
    and stops the server through :attr:`should_exit`."""

    @contextlib.contextmanager
    def capture_signals(self) -> Generator[None, None, None]:
        yield


def listen(settings: DashboardSettings) -> socket.socket:
    """The listening socket, opened here so that a port in use is one clear error."""
    try:
        infos = socket.getaddrinfo(settings.host, settings.port, type=socket.SOCK_STREAM)
        family = infos[0][0]
        sock = socket.create_server((settings.host, settings.port), family=family)
    except OSError as exc:
        raise ConnectionFailure(
            f"the dashboard cannot listen on {settings.host}:{settings.port}: {exc} "
            "(PNAV_DASHBOARD_PORT, `pnav up --http-port`)"
        ) from exc
    sock.setblocking(False)
    return sock


class Dashboard:
    def __init__(
        self,
        runtime: Runtime,
        settings: DashboardSettings,
        *,
        extra_routes: Sequence[BaseRoute] = (),
        observers: Sequence[Observer] = (),
    ) -> None:
        self.runtime, self.settings = runtime, settings
        self.store = DashboardStore(PgDashboardSource(runtime.database))
        self.hub = Hub()
        self.observers = list(observers)
        self.app = create_app(self.store, self.hub, extra_routes, AllowedHosts.of(settings))
        self.port = settings.port

    def on_message(self, key: str, payload: bytes) -> None:
        try:
            note = Notification.decode(key, payload)
        except ValueError:
            return  # not a notification key, or an unreadable payload: nothing to show
        self.store.note(note)
        for observer in self.observers:
            try:
                observer(note)
            except Exception:
                logger.warning("a notification observer failed", exc_info=True)

    async def push(self) -> None:
        """One push: read what is marked, re-read everything when due, send what changed."""
        store = self.store
        if time.monotonic() - store.refreshed_at >= self.settings.refresh_period_s:
            await store.refresh()
        await store.flush()
        if self.hub.browsers:
            self.hub.broadcast(store.take_updates())
        else:
            store.skip_updates()  # a browser that comes gets a snapshot

    async def _push_loop(self) -> None:
        failing = False
        while True:
            try:
                await self.push()
                if failing:
                    log.event(logger, logging.INFO, "the database answers again")
                failing = False
            except Exception as exc:
                if not failing:
                    logger.warning("cannot read the contract tables: %s", exc)
                failing = True
            await asyncio.sleep(self.settings.push_period_s)

    async def run(self, stop: asyncio.Event) -> None:
        sock = listen(self.settings)
        self.port = sock.getsockname()[1]
        subscriber = bus.subscribe(self.runtime.zenoh, keys.NOTIFY_ALL, self.on_message)
        self.runtime.on_close(subscriber.undeclare)
        config = uvicorn.Config(
            self.app, log_level="warning", lifespan="off", ws="websockets-sansio"
        )
        server = _Server(config)
        pusher = asyncio.create_task(self._push_loop(), name="dashboard-push")
        serving = asyncio.create_task(server.serve(sockets=[sock]), name="dashboard-http")
        host = f"[{self.settings.host}]" if ":" in self.settings.host else self.settings.host
        log.event(logger, logging.INFO, "dashboard up", url=f"http://{host}:{self.port}/")
        stopping = asyncio.create_task(stop.wait(), name="stop")
        try:
            done, _ = await asyncio.wait({serving, stopping}, return_when=asyncio.FIRST_COMPLETED)
            if serving in done:
                serving.result()
                raise ConnectionFailure("the dashboard's HTTP server stopped by itself")
        finally:
            stopping.cancel()
            self.hub.close()  # every websocket ends, so the server has nothing to wait for
            server.should_exit = True
            with contextlib.suppress(Exception):
                await asyncio.wait_for(serving, 10)
            pusher.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await pusher
            sock.close()


async def serve(
    config: ServiceConfig,
    stop: asyncio.Event,
    *,
    extra_routes: Sequence[BaseRoute] = (),
    observers: Sequence[Observer] = (),
) -> None:
    settings = DashboardSettings.from_env()
    runtime = await Runtime.open(config)
    # GET /metrics on the dashboard's port (docs/METRICS.md): it sees every notification too
    metrics = Metrics(MetricsConfig.from_env())
    try:
        await metrics.start(runtime.database.pool, runtime.zenoh)
        dashboard = Dashboard(
            runtime,
            settings,
            extra_routes=[*metrics.routes(), *extra_routes],
            observers=[metrics.note, *observers],
        )
        await dashboard.run(stop)
    finally:
        await metrics.close()
        await runtime.close()


def main(argv: list[str] | None = None) -> int:
    return run_service(SERVICE, serve, argv)


if __name__ == "__main__":
    sys.exit(main())

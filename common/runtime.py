"""What every service process needs: connections, a liveliness token, signals, clean exit.

:class:`Runtime` owns the Postgres pool, the Zenoh session, the notifier, the sim clock, the
liveliness token ``pnav/alive/{service}/{instance}`` and, in a lockstep run, the ledger
(common.lockstep) it hands to the notifier and the clock. :func:`run_service` is the process
entry point: structured logs, uvloop, SIGINT/SIGTERM handlers that ask the service to stop,
and an exit code (0 clean, 1 failed, 2 misconfigured).
"""

from __future__ import annotations

import asyncio
import logging
import os
import signal
import sys
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

import uvloop
import zenoh

from common import bus, lockstep, log
from common.clock import SimClock
from common.config import ServiceConfig
from common.contract import keys
from common.db import Database, create_pool, lock_settings
from common.errors import ConnectionFailure, UsageError
from common.lifeline import die_with_parent
from common.outage import fold_outage_logs

T = TypeVar("T")
logger = logging.getLogger("pnav.runtime")


class Runtime:
    """Connections of one service process. Build with :meth:`open`, end with :meth:`close`."""

    def __init__(self, config: ServiceConfig) -> None:
        self.config = config
        self.session: zenoh.Session | None = None
        self.db: Database | None = None
        self.clock = SimClock()
        self._token: Any = None
        # taking part in a lockstep run: hand it to every subscription (bus.subscribe)
        self.ledger: lockstep.Ledger | None = None
        self._closers: list[Callable[[], Any]] = []
        # a host's session (pnav.run.host) is the host's to close, not this service's
        self._owns_session = True

    @classmethod
    async def open(
        cls,
        config: ServiceConfig,
        *,
        with_db: bool = True,
        receipts: bool = True,
        session: zenoh.Session | None = None,
    ) -> Runtime:
        """Connect. With ``config.lockstep`` set the process takes part in a lockstep run: the
        runtime makes its :attr:`ledger` (common.lockstep) and hands it to the sim clock and
        the notifier; whoever subscribes or reports passes it on. ``receipts=False``: a
        sender-only participant (a benchmark runner), whose subscriptions are not counted.
        ``session``: a Zenoh session shared with the other services of a host process
        (pnav.run.host), used instead of one of its own and left open by :meth:`close`."""
        runtime = cls(config)
        try:
            if session is not None:
                runtime.session, runtime._owns_session = session, False
            else:
                # Zenoh's open blocks while it connects: keep the loop free meanwhile.
                runtime.session = await asyncio.to_thread(bus.open_session, config.zenoh)
            if config.lockstep:
                runtime.ledger = lockstep.Ledger(
                    runtime.session, config.service, config.instance, receipts=receipts
                )
            runtime.clock.attach(runtime.session, runtime.ledger)
            if with_db:
                pool = await create_pool(
                    config.database_url,
                    max_size=config.pool_max,
                    wait_s=config.db_wait_s,
                    server_settings=lock_settings(config.db_lock_timeout_ms),
                )
                runtime.db = Database(
                    pool,
                    bus.Notifier(runtime.session, runtime.ledger, images=config.notify_images),
                )
            runtime._token = runtime.session.liveliness().declare_token(
                keys.alive_key(config.service, config.instance)
            )
        except BaseException:
            await runtime.close()
            raise
        log.event(
            logger,
            logging.INFO,
            "connected",
            service=config.service,
            instance=config.instance,
            zenoh=",".join(config.zenoh.connect),
        )
        return runtime

    @property
    def zenoh(self) -> zenoh.Session:
        if self.session is None:
            raise ConnectionFailure("the Zenoh session is not open")
        return self.session

    @property
    def database(self) -> Database:
        if self.db is None:
            raise ConnectionFailure("this runtime was opened without a database")
        return self.db

    def on_close(self, closer: Callable[[], Any]) -> None:
        """Run ``closer()`` (e.g. ``subscriber.undeclare``) first thing in :meth:`close`."""
        self._closers.append(closer)

    async def close(self) -> None:
        """Undeclare everything, close the pool, then the session; safe to call twice."""
        for closer in reversed(self._closers):
            try:
                result = closer()
                if asyncio.iscoroutine(result):
                    await result
            except Exception:
                logger.warning("closing %r failed", closer, exc_info=True)
        self._closers.clear()
        self.clock.close()
        if self.ledger is not None:
            ledger, self.ledger = self.ledger, None
            ledger.close()
        if self._token is not None:
            try:
                self._token.undeclare()
            except Exception:
                logger.debug("liveliness token undeclare failed", exc_info=True)
            self._token = None
        if self.db is not None:
            self.db.notifier.close()
            await self.db.close()
            self.db = None
        if self.session is not None:
            session, self.session = self.session, None
            if self._owns_session:
                await asyncio.to_thread(session.close)


ServiceMain = Callable[[ServiceConfig, asyncio.Event], Awaitable[None]]

# How long a service may take to drain once asked to stop before its process leaves anyway.
# A stop can find Postgres or the router gone (the launcher was killed, and its lifeline
# stopped Postgres): a start still waiting for them, or a last write, would wait for ever,
# and a process whose launcher is gone has nobody left to kill it. Longer than the
# supervisor's own grace (pnav.run.process_supervisor), which kills a slower one first.
STOP_LIMIT_S = 20.0
# A service's entry as a host process starts it (pnav.run.host, entry point group
# ``pnav.services``): ``serve(config, stop, session)``, the session being the host's.
HostedMain = Callable[[ServiceConfig, asyncio.Event, "zenoh.Session | None"], Awaitable[None]]


def _stop_limit_s() -> float:
    raw = os.environ.get("PNAV_STOP_LIMIT_S", "").strip()
    try:
        return float(raw) if raw else STOP_LIMIT_S
    except ValueError:
        return STOP_LIMIT_S


async def until_stopped(
    work: Awaitable[T],
    stop: asyncio.Event,
    limit_s: float,
    leave: Callable[[int], Any] = os._exit,
) -> T:
    """Await ``work``; once ``stop`` is set, give it ``limit_s`` to return, then leave the
    process (exit code 1, logged): a drain that cannot end must not keep it alive."""
    task = asyncio.ensure_future(work)
    asked = asyncio.ensure_future(stop.wait())
    try:
        await asyncio.wait({task, asked}, return_when=asyncio.FIRST_COMPLETED)
        if not task.done():
            done, _ = await asyncio.wait({task}, timeout=limit_s)
            if not done:
                logger.error("did not stop within %.1f s of being asked to; leaving", limit_s)
                logging.shutdown()
                leave(1)
    finally:
        asked.cancel()
    return await task


def run_stoppable(work: Callable[[asyncio.Event], Awaitable[T]]) -> tuple[int, T | None]:
    """Run ``work(stop)`` under uvloop until it returns, SIGINT and SIGTERM setting ``stop``
    (it then has PNAV_STOP_LIMIT_S to return: :func:`until_stopped`). The exit code and what
    ``work`` returned: 0 and its value; 2 (a UsageError) or 1 (a ConnectionFailure), logged,
    and None. Any other exception is the caller's."""

    async def runner() -> T:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        return await until_stopped(work(stop), stop, _stop_limit_s())

    try:
        return 0, uvloop.run(runner())
    except UsageError as exc:
        logger.error("%s", exc)
        return 2, None
    except ConnectionFailure as exc:
        logger.error("%s", exc)
        return 1, None


def run_service(service: str, main: ServiceMain, argv: list[str] | None = None) -> int:
    """Run ``main(config, stop_event)`` under uvloop until it returns; return an exit code.

    SIGINT and SIGTERM set ``stop_event``; ``main`` is expected to drain and return.
    """
    die_with_parent()
    try:
        config = ServiceConfig.from_env(service)
    except UsageError as exc:
        print(f"{service}: {exc}", file=sys.stderr)
        return 2
    log.setup(service, config.log_level)
    # while Postgres is down, lines that only repeat so are counted, not printed
    fold_outage_logs()
    try:
        code, _ = run_stoppable(lambda stop: main(config, stop))
    except Exception:
        logger.exception("service failed")
        return 1
    if code == 0:
        log.event(logger, logging.INFO, "stopped", service=service)
    return code

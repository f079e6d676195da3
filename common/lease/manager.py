"""LeaseManager: the robots one replica owns, kept fair with its siblings (see the package
docstring for the protocol and for why ownership is trusted, and taken over, as it is)."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable

import asyncpg

from common import log
from common.config import LeaseSettings
from common.contract import keys
from common.errors import ConnectionFailure
from common.lease.cycle import Cycle, LeaseCounters, UnderWay
from common.lease.holdings import Holdings
from common.lease.session import LockSession, statement_timeout
from common.lease.sql import SHUTDOWN

logger = logging.getLogger("pnav.lease")

OwnershipListener = Callable[[frozenset[str], frozenset[str]], None]
Notify = Callable[[str, str | None, int | None], None]

# A replica trusts its ownership this fraction of timeout_s after its last confirmed cycle;
# a takeover from a holder that vanished waits as long (CONTRACT.md, *Robot leases*).
TRUST_FRACTION = 0.8


class LeaseManager:
    """The robots one replica of ``service`` owns, kept fair with its siblings.

    ``on_change(gained, lost)`` runs on the loop whenever the robots it acts for change: a
    lost robot is reported *before* its lock is given back (stop acting first), a gained one
    once its lock is held and any takeover wait is over. ``under_way()`` gives the work under
    way (the engine's activation, :meth:`Engine.under_way`): a robot given back keeps its
    lock until that work has ended (the hand-over, common.lease.cycle), so its next owner
    reads every row it wrote. ``notify(table, robot, id)``
    announces robot_lease writes (the contract's change notification). Use :meth:`start` /
    :meth:`stop`, or ``async with``.
    """

    def __init__(
        self,
        url: str,
        service: str,
        instance: str,
        settings: LeaseSettings | None = None,
        *,
        on_change: OwnershipListener | None = None,
        under_way: UnderWay | None = None,
        notify: Notify | None = None,
        connect_wait_s: float = 10.0,
        settle_cycles: int = 2,
    ) -> None:
        self.url = url
        self.service = service
        self.instance = instance
        self.settings = settings or LeaseSettings()
        self.on_change = on_change
        self.notify = notify
        self.connect_wait_s = connect_wait_s
        self.settle_cycles = settle_cycles
        self.counters = LeaseCounters()
        self.valid_s = TRUST_FRACTION * self.settings.timeout_s
        self._session: LockSession | None = None
        self._old_pid: int | None = None  # backend of a session lost, to clean up after
        self._held = Holdings(self._changed)
        self._cycle = Cycle(
            service,
            instance,
            self._held,
            self.counters,
            self._notify,
            settle_cycles=settle_cycles,
            takeover_wait_s=self.valid_s,
            under_way=under_way,
            wake=self.poke,
        )
        self._confirmed_at = 0.0  # monotonic start of the last cycle that saw our locks
        self._poke = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._lock = asyncio.Lock()  # one cycle (or stop) at a time on the connection
        self._closing = False
        self._failures = 0  # losses and failed reconnects since the last good cycle
        self._retry_at = 0.0

    # -- what services ask ------------------------------------------------------------------
    def owns(self, robot_id: str) -> bool:
        """Whether this replica acts for ``robot_id`` now: it holds its lock on a live,
        freshly confirmed connection, and any takeover wait is over."""
        return robot_id in self._held and self._trusted()

    @property
    def owned(self) -> frozenset[str]:
        return self._held.acting() if self._trusted() else frozenset()

    @property
    def waiting(self) -> frozenset[str]:
        """Robots taken over from a holder that vanished, not acted on yet."""
        return frozenset(self._held.waiting)

    @property
    def handing_over(self) -> frozenset[str]:
        """Robots given back whose lock waits for the work under way to end."""
        return frozenset(self._cycle.handing)

    @property
    def replicas(self) -> int:
        """Live replicas of the service (this one included) seen by the last cycle."""
        return self._cycle.members

    @property
    def share(self) -> tuple[int, int]:
        return self._cycle.share

    @property
    def backend_pid(self) -> int | None:
        """Backend pid of the lock connection (``pg_locks.pid``, ``robot_lease.backend_pid``)."""
        return None if self._session is None else self._session.pid

    @property
    def connected(self) -> bool:
        return self._session is not None and self._session.alive

    def _trusted(self) -> bool:
        fresh = time.monotonic() - self._confirmed_at < self.valid_s
        return fresh and self.connected

    # -- lifecycle ---------------------------------------------------------------------------
    async def start(self) -> None:
        """Connect, join, and run one cycle at once (a lone replica owns every robot when
        this returns, unless it takes them over from a vanished holder); then keep cycling
        in the background."""
        self._loop = self._held.loop = asyncio.get_running_loop()
        self._closing = False
        try:
            await self._open(self.connect_wait_s)
            async with self._lock:
                await self._step()
        except BaseException:
            self._terminate()
            raise
        self._task = asyncio.create_task(self._run(), name=f"leases-{self.service}")

    async def stop(self) -> None:
        """Give every robot back (history closed as ``shutdown``), leave, close."""
        self._closing = True
        self._poke.set()
        task, self._task = self._task, None
        if task is not None:
            try:
                # the loop ends after the cycle under way, never in the middle of a lock call
                await asyncio.wait_for(asyncio.shield(task), statement_timeout(self.settings) * 2)
            except TimeoutError:
                task.cancel()
            except asyncio.CancelledError:
                if not task.cancelled():
                    raise  # we are being cancelled ourselves
            with contextlib.suppress(asyncio.CancelledError):
                await task
        async with self._lock:
            session, self._session = self._session, None
            owned = sorted(self._forget_all())
            if session is None or not session.alive:
                return
            try:
                await self._cycle.release(session, owned, SHUTDOWN)
                await session.leave(SHUTDOWN)
            except ConnectionFailure:
                logger.warning("lease connection did not close cleanly", exc_info=True)
        if owned:
            self._event(logging.INFO, "leases released", robots=",".join(owned))

    def _terminate(self) -> None:
        session, self._session = self._session, None
        self._closing = True
        self._held.clear()
        if session is not None:
            session.terminate()

    async def __aenter__(self) -> LeaseManager:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    def poke(self) -> None:
        """Run a cycle now rather than at the end of the period (call on the loop)."""
        self._poke.set()

    def poke_threadsafe(self) -> None:
        """:meth:`poke` from any thread (a Zenoh callback)."""
        loop = self._loop
        if loop is not None:
            with contextlib.suppress(RuntimeError):  # loop closed: shutting down
                loop.call_soon_threadsafe(self._poke.set)

    # -- the connection -----------------------------------------------------------------------
    async def _open(self, wait_s: float = 0.0) -> None:
        session, closed = await LockSession.open(
            self.url,
            self.service,
            self.instance,
            self.settings,
            old_pid=self._old_pid,
            on_closed=self._on_closed,
            wait_s=wait_s,
        )
        self._session, self._old_pid = session, None
        for robot in closed:
            self._notify(robot, None)
        self._event(logging.INFO, "lease connection open", backend_pid=session.pid)

    def _on_closed(self, conn: asyncpg.Connection) -> None:
        # asyncpg calls this when the socket closes; a session ended while the connection
        # was idle may only show as a failed query (LockSession), which drops us too
        session = self._session
        if session is not None and session.conn is conn and not self._closing:
            self._lost("the lock connection closed")

    def _forget_all(self) -> frozenset[str]:
        """Stop acting for every robot (reported lost); return the robots whose lock we held
        (handed over or not)."""
        self._confirmed_at = 0.0
        self._cycle.pending = 0
        return self._held.clear() | self._cycle.forget_handovers()

    def _lost(self, why: str) -> None:
        """The lock connection is gone or unusable: stop acting for every robot at once, close
        it, and reconnect (at once the first time, then backing off)."""
        session, self._session = self._session, None
        if session is None and not self._held.owned:
            return  # already handled (the termination listener, then the failed query)
        if session is not None:
            self._old_pid = session.pid
            session.terminate()
        lost = self._forget_all()
        self.counters.lost += len(lost)
        self._failures += 1
        self._retry_at = time.monotonic() + self._backoff()
        self._event(logging.WARNING, "leases lost", why=why, robots=",".join(sorted(lost)) or "-")
        self._poke.set()

    def _backoff(self) -> float:
        if self._failures <= 1:
            return 0.0
        return min(self.settings.period_s * 2.0 ** (self._failures - 2), 5.0)

    # -- the cycle ----------------------------------------------------------------------------
    async def _run(self) -> None:
        while not self._closing:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._poke.wait(), self.settings.period_s)
            self._poke.clear()
            async with self._lock:
                if self._closing:
                    return
                await self._step()
            # at most one cycle per 50 ms, however often we are poked
            await asyncio.sleep(0.05)

    async def _step(self) -> None:
        """One cycle, reconnecting first if needed. Never raises: whatever fails, the robots
        are dropped and the connection is opened again."""
        if self._session is None:
            if time.monotonic() < self._retry_at:
                return
            try:
                await self._open()
            except Exception as exc:
                self._failures += 1
                self._retry_at = time.monotonic() + self._backoff()
                logger.warning("lease reconnect failed: %r", exc)
                return
            self.counters.reconnects += 1
        try:
            await self._read_and_act()
        except Exception as exc:
            if not isinstance(exc, ConnectionFailure):
                self.counters.errors += 1
                logger.error("lease cycle failed", exc_info=True)
            self._lost(f"cycle failed: {exc!r}")
        else:
            self._failures = 0

    async def _read_and_act(self) -> None:
        session = self._session
        if session is None:
            return
        started = time.monotonic()
        view = await session.snapshot()
        self._confirmed_at = started
        await self._cycle.run(session, view)

    # -- reporting ------------------------------------------------------------------------------
    def _event(self, level: int, what: str, **fields: object) -> None:
        log.event(logger, level, what, service=self.service, instance=self.instance, **fields)

    def _changed(self, gained: frozenset[str], lost: frozenset[str]) -> None:
        if self.on_change is not None:
            try:
                self.on_change(gained, lost)
            except Exception:
                logger.exception("ownership listener failed")

    def _notify(self, robot: str, row_id: int | None) -> None:
        if self.notify is not None:
            try:
                self.notify(keys.ROBOT_LEASE, robot, row_id)
            except Exception:
                logger.debug("robot_lease notification failed", exc_info=True)

"""Robot leases: replicas of one scenario service split the robots between them.

The protocol is the contract's (CONTRACT.md, *Robot leases*; migration 2); this module is
its Python side. In short:

- A replica owns robot R of service S exactly while its **one dedicated Postgres connection**
  (never a pooled one: a pooled connection's session locks would leak to whoever borrows it
  next) holds the session-level advisory lock ``(lease_key(S), lease_key(R))``. Postgres is
  the only judge of who owns what; there is no election, no heartbeat table, no consensus of
  our own.
- It counts as a live replica while that connection holds ``(lease_key(S), 0)`` shared. So
  the number of replicas comes from the same place as the locks and dies with them: a
  replica whose lock connection is gone is neither an owner nor counted, at the same instant.
  (Zenoh liveliness tokens would be a second, independent view of who is alive; they can
  disagree with the locks for seconds, e.g. a replica with a live Zenoh session whose lock
  connection is reconnecting, and the others would then leave its share unowned. Here they
  only *hint* that it is worth looking again now: :meth:`LeaseManager.poke`.)
- Every ``period_s`` of wall time a cycle reads the robots and ``pg_locks`` in one query,
  computes the fair share (:func:`fair_share`, :func:`decide`), takes free robots with
  ``pg_try_advisory_lock`` (through ``robot_lease_acquire``, which also writes the history
  row) and gives back robots above the share, only once the excess has lasted
  ``settle_cycles`` cycles (hysteresis).
- The lock connection runs with ``idle_session_timeout`` = ``timeout_s``: a replica that
  stops talking to Postgres (hung, partitioned) loses its session and so its robots; the
  replica itself stops trusting its ownership after 80 % of that since its last confirmed
  cycle. If the connection is lost, every robot is dropped at once, then it reconnects.

:class:`LeaseManager` runs on the service's event loop; :class:`common.service.ScenarioService`
starts it before the engine's first activation and exposes ``owns(robot_id)``.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import asyncpg

from common import log
from common.config import LeaseSettings
from common.contract import keys
from common.errors import ConnectionFailure

logger = logging.getLogger("pnav.lease")

# Reasons written to robot_lease.reason.
REBALANCE = "rebalance"
SHUTDOWN = "shutdown"
CONNECTION_LOST = "connection lost"
ROBOT_GONE = "robot gone"

# Errors that mean the lock connection is gone or unusable: drop everything, reconnect.
_CONNECTION_ERRORS = (
    asyncpg.PostgresConnectionError,
    asyncpg.InterfaceError,
    asyncpg.AdminShutdownError,
    asyncpg.CannotConnectNowError,
    ConnectionError,
    OSError,
    TimeoutError,
)

OwnershipListener = Callable[[frozenset[str], frozenset[str]], None]
Notify = Callable[[str, str | None, int | None], None]


# -- keys and arithmetic (pure) -------------------------------------------------------------
def lease_key(name: str) -> int:
    """The contract's ``lease_key(name)``: the first 31 bits of sha256(name), never 0."""
    digest = hashlib.sha256(name.encode()).digest()
    return max(1, int.from_bytes(digest[:4], "big") & 0x7FFFFFFF)


def fair_share(robots: int, replicas: int) -> tuple[int, int]:
    """``(floor, ceil)`` of robots per replica; every replica should own between the two."""
    n = max(1, replicas)
    return robots // n, -(-robots // n)


def affinity(instance: str, robot: str) -> int:
    """Rendezvous score: replicas try free robots in different orders (fewer collisions), and
    a replica that keeps its instance id (``controller-2``) tends to get its robots back."""
    return int.from_bytes(hashlib.sha256(f"{instance}\0{robot}".encode()).digest()[:8], "big")


@dataclass(frozen=True)
class Snapshot:
    """One cycle's view of Postgres: every robot, who holds it, who is a live replica."""

    robots: tuple[str, ...]
    holders: Mapping[str, int | None]  # robot -> backend pid holding its lock, or None
    members: frozenset[int]  # backend pids holding the membership lock
    me: int  # our lock connection's backend pid


@dataclass(frozen=True)
class Decision:
    acquire: tuple[str, ...] = ()  # free robots to try, best first
    want: int = 0  # how many of them to take
    release: tuple[str, ...] = ()  # robots to give back now
    pending: int = 0  # consecutive cycles the release condition has held
    share: tuple[int, int] = (0, 0)
    replicas: int = 1


def decide(
    view: Snapshot, owned: frozenset[str], instance: str, pending: int, settle_cycles: int
) -> Decision:
    """What this replica should take and give back this cycle.

    With R robots and N live replicas, ``lo, hi = fair_share(R, N)``:

    - take free robots up to ``lo``; beyond it, up to ``hi``, only those left once every
      other replica below ``lo`` could reach it (the poorer pick first);
    - give back robots above ``hi``; and, when another replica is below ``lo`` and no robot
      is free, the richest replica (ties: lowest backend pid) gives back one above ``lo``;
    - a give-back happens only when its condition has held ``settle_cycles`` cycles in a
      row (``pending`` counts them), so a replica that joins and leaves, or a transient
      view, does not make ownership flap. Taking is immediate: that is the takeover.
    """
    members = set(view.members) | {view.me}
    lo, hi = fair_share(len(view.robots), len(members))
    mine = [r for r in view.robots if r in owned]
    count = len(mine)
    counts = dict.fromkeys(members, 0)
    for robot in view.robots:
        holder = view.holders.get(robot)
        if holder is not None and holder in counts:
            counts[holder] += 1
    counts[view.me] = count
    others = [c for pid, c in counts.items() if pid != view.me]
    free = [
        r
        for r in view.robots
        if view.holders.get(r) is None or (view.holders.get(r) == view.me and r not in owned)
    ]
    deficit_others = sum(max(0, lo - c) for c in others)
    floor_need = max(0, lo - count)
    spare = len(free) - deficit_others - floor_need
    extra = max(0, min(hi - max(count, lo), spare))
    want = min(len(free), floor_need + extra)

    give = 0
    if count > hi:
        give = count - hi
    elif count > lo and any(c < lo for c in others) and len(free) < deficit_others:
        richest = max(counts.values())
        if count == richest and view.me == min(p for p, c in counts.items() if c == richest):
            give = 1
    pending = pending + 1 if give else 0
    release: tuple[str, ...] = ()
    if give and pending >= settle_cycles:
        release = tuple(sorted(mine, key=lambda r: affinity(instance, r))[:give])
        pending = 0
    acquire = tuple(sorted(free, key=lambda r: affinity(instance, r), reverse=True))
    return Decision(acquire, want, release, pending, (lo, hi), len(members))


# -- SQL ------------------------------------------------------------------------------------
# One read per cycle: every robot with the backend holding its lock, then the live replicas.
# pg_locks is read once (the CTE is materialised), so the two halves agree.
_HELD = f"""
held AS (
    SELECT l.objid::bigint AS k, l.pid, l.mode
      FROM pg_locks l
     WHERE l.locktype = 'advisory' AND l.granted AND l.objsubid = 2
       AND l.database = (SELECT oid FROM pg_database WHERE datname = current_database())
       AND l.classid = {keys.LEASE_KEY_FN}($1)::oid
)"""
_SNAPSHOT = f"""
WITH {_HELD}
SELECT r.robot_id, h.pid
  FROM {keys.ROBOT} r
  LEFT JOIN held h ON h.k = {keys.LEASE_KEY_FN}(r.robot_id) AND h.mode = 'ExclusiveLock'
UNION ALL
SELECT NULL, h.pid FROM held h WHERE h.k = {keys.LEASE_MEMBER_KEY} AND h.mode = 'ShareLock'
"""
_JOIN = f"SELECT pg_try_advisory_lock_shared({keys.LEASE_KEY_FN}($1), {keys.LEASE_MEMBER_KEY})"
_LEAVE = f"SELECT pg_advisory_unlock_shared({keys.LEASE_KEY_FN}($1), {keys.LEASE_MEMBER_KEY})"
_ACQUIRE = f"SELECT {keys.LEASE_ACQUIRE_FN}($1, $2, $3)"
_RELEASE = f"SELECT {keys.LEASE_RELEASE_FN}($1, $2, $3)"
# After a reconnect: end what an earlier session of ours left (if it is still there, it is
# told to go first, so its locks cannot outlive it for the idle timeout).
_END_OLD_SESSION = """
SELECT pg_terminate_backend(pid) FROM pg_stat_activity
 WHERE pid = $1 AND application_name = $2 AND pid <> pg_backend_pid()
"""
_CLOSE_MINE = f"""
UPDATE {keys.ROBOT_LEASE} SET released_at = clock_timestamp(), reason = $2
 WHERE service = $1 AND backend_pid = pg_backend_pid() AND released_at IS NULL
"""
_CLOSE_OLD_ROWS = f"""
UPDATE {keys.ROBOT_LEASE} SET released_at = clock_timestamp(), reason = $4
 WHERE service = $1 AND instance = $2 AND backend_pid = $3 AND released_at IS NULL
RETURNING robot_id
"""


@dataclass
class LeaseCounters:
    cycles: int = 0
    acquired: int = 0
    released: int = 0
    lost: int = 0  # robots dropped because the lock connection went
    reconnects: int = 0
    errors: int = 0


@dataclass
class _State:
    owned: set[str] = field(default_factory=set)
    pending: int = 0
    members: int = 0
    share: tuple[int, int] = (0, 0)


class LeaseManager:
    """The robots one replica of ``service`` owns, kept fair with its siblings.

    ``on_change(gained, lost)`` runs on the loop whenever ownership changes: a lost robot is
    reported *before* its lock is given back (stop acting first), a gained one after it is
    taken. ``notify(table, robot, id)`` announces robot_lease writes (the contract's change
    notification). Use :meth:`start` / :meth:`stop`, or ``async with``.
    """

    def __init__(
        self,
        url: str,
        service: str,
        instance: str,
        settings: LeaseSettings | None = None,
        *,
        on_change: OwnershipListener | None = None,
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
        self.application_name = f"pnav-lease {service}/{instance}"[:63]
        self._conn: asyncpg.Connection | None = None
        self._pid: int | None = None
        self._old_pid: int | None = None  # backend of a session lost, to clean up after
        self._state = _State()
        self._confirmed_at = 0.0  # monotonic start of the last cycle that saw our locks
        self._valid_s = 0.8 * self.settings.timeout_s
        self._poke = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._lock = asyncio.Lock()  # one cycle (or stop) at a time on the connection
        self._closing = False
        self._retry_s = self.settings.period_s
        self._retry_at = 0.0

    # -- what services ask ------------------------------------------------------------------
    def owns(self, robot_id: str) -> bool:
        """Whether this replica handles ``robot_id`` now (holds its lock, freshly confirmed)."""
        return robot_id in self._state.owned and self._fresh()

    @property
    def owned(self) -> frozenset[str]:
        return frozenset(self._state.owned) if self._fresh() else frozenset()

    @property
    def replicas(self) -> int:
        """Live replicas of the service (this one included) seen by the last cycle."""
        return self._state.members

    @property
    def share(self) -> tuple[int, int]:
        return self._state.share

    @property
    def backend_pid(self) -> int | None:
        """Backend pid of the lock connection (``pg_locks.pid``, ``robot_lease.backend_pid``)."""
        return self._pid

    @property
    def connected(self) -> bool:
        return self._conn is not None and not self._conn.is_closed()

    def _fresh(self) -> bool:
        return time.monotonic() - self._confirmed_at < self._valid_s

    # -- lifecycle ---------------------------------------------------------------------------
    async def start(self) -> None:
        """Connect, join, and run one cycle at once (a lone replica owns every robot when
        this returns); then keep cycling in the background."""
        self._loop = asyncio.get_running_loop()
        self._closing = False
        deadline = time.monotonic() + self.connect_wait_s
        try:
            while True:
                try:
                    await self._connect()
                    break
                except _CONNECTION_ERRORS as exc:
                    if time.monotonic() >= deadline:
                        raise ConnectionFailure(
                            f"{self.service}: cannot open the lease connection: {exc}"
                        ) from exc
                    await asyncio.sleep(0.2)
            async with self._lock:
                try:
                    await self._cycle()
                except _CONNECTION_ERRORS as exc:
                    self._lost(f"first cycle failed: {exc!r}")
        except asyncpg.UndefinedFunctionError as exc:
            self._terminate()
            raise ConnectionFailure(
                f"the database has no robot leases (contract migration 2): run `pnav migrate` "
                f"({exc})"
            ) from exc
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
                await asyncio.wait_for(asyncio.shield(task), self._timeout * 2)
            except TimeoutError:
                task.cancel()
            except asyncio.CancelledError:
                if not task.cancelled():
                    raise  # we are being cancelled ourselves
            with contextlib.suppress(asyncio.CancelledError):
                await task
        async with self._lock:
            conn = self._conn
            owned = sorted(self._state.owned)
            self._state = _State()
            self._confirmed_at = 0.0
            if owned:
                self._changed(frozenset(), frozenset(owned))
            if conn is None or conn.is_closed():
                self._conn = None
                return
            try:
                for robot in owned:
                    await self._release(conn, robot, SHUTDOWN)
                # a lock taken by a call whose answer never came back: closing frees it;
                # close its history row too
                await conn.execute(_CLOSE_MINE, self.service, SHUTDOWN, timeout=self._timeout)
                await conn.fetchval(_LEAVE, self.service, timeout=self._timeout)
                await asyncio.wait_for(conn.close(), self._timeout)
            except Exception:
                logger.warning("lease connection did not close cleanly", exc_info=True)
                conn.terminate()
            finally:
                self._conn = None
        if owned:
            log.event(
                logger,
                logging.INFO,
                "leases released",
                service=self.service,
                robots=",".join(owned),
            )

    def _terminate(self) -> None:
        conn, self._conn = self._conn, None
        self._closing = True
        if conn is not None and not conn.is_closed():
            conn.terminate()

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
    @property
    def _timeout(self) -> float:
        # a statement slower than this means the connection is not usable for leases
        return max(1.0, self.settings.timeout_s / 2)

    async def _connect(self) -> None:
        conn: asyncpg.Connection = await asyncpg.connect(
            self.url,
            timeout=self._timeout,
            server_settings={"application_name": self.application_name},
        )
        try:
            # Postgres ends the session (and so frees our robots) if we go silent
            try:
                await conn.execute(
                    f"SET idle_session_timeout = {int(self.settings.timeout_s * 1000)}",
                    timeout=self._timeout,
                )
            except asyncpg.UndefinedObjectError:  # Postgres before 14
                logger.warning(
                    "this Postgres has no idle_session_timeout (14+): a hung replica keeps "
                    "its robots until its connection closes"
                )
            pid = int(await conn.fetchval("SELECT pg_backend_pid()", timeout=self._timeout))
            if self._old_pid is not None:
                try:
                    await conn.fetchval(
                        _END_OLD_SESSION,
                        self._old_pid,
                        self.application_name,
                        timeout=self._timeout,
                    )
                except asyncpg.InsufficientPrivilegeError:
                    pass  # another role's backend: the idle timeout will end it
                closed = await conn.fetch(
                    _CLOSE_OLD_ROWS,
                    self.service,
                    self.instance,
                    self._old_pid,
                    CONNECTION_LOST,
                    timeout=self._timeout,
                )
                for row in closed:
                    self._notify(row["robot_id"], None)
            if not await conn.fetchval(_JOIN, self.service, timeout=self._timeout):
                raise ConnectionFailure("the membership lock is held exclusively")
        except BaseException:
            conn.terminate()
            raise
        conn.add_termination_listener(self._on_terminated)
        self._conn, self._pid, self._old_pid = conn, pid, None
        self._retry_s = self.settings.period_s
        log.event(
            logger,
            logging.INFO,
            "lease connection open",
            service=self.service,
            instance=self.instance,
            backend_pid=pid,
        )

    def _on_terminated(self, conn: asyncpg.Connection) -> None:
        # asyncpg calls this when the connection closes, for any reason
        if conn is self._conn and not self._closing:
            self._lost("the lock connection closed")

    def _lost(self, why: str) -> None:
        """The lock connection is gone: stop acting for every robot at once."""
        if self._conn is None and not self._state.owned:
            return  # already handled (the termination listener, then the failed query)
        conn, self._conn = self._conn, None
        if self._pid is not None:
            self._old_pid = self._pid
        self._pid = None
        if conn is not None and not conn.is_closed():
            conn.terminate()
        lost = frozenset(self._state.owned)
        self._state = _State()
        self._confirmed_at = 0.0
        self.counters.lost += len(lost)
        self._retry_at = time.monotonic()
        log.event(
            logger,
            logging.WARNING,
            "leases lost",
            service=self.service,
            instance=self.instance,
            why=why,
            robots=",".join(sorted(lost)) or "-",
        )
        if lost:
            self._changed(frozenset(), lost)
        self._poke.set()

    # -- the cycle ----------------------------------------------------------------------------
    async def _run(self) -> None:
        period = self.settings.period_s
        while not self._closing:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._poke.wait(), period)
            self._poke.clear()
            async with self._lock:
                if self._closing:
                    return
                if self._conn is None:
                    if time.monotonic() < self._retry_at:
                        continue
                    try:
                        await self._connect()
                        self.counters.reconnects += 1
                    except Exception as exc:
                        self._retry_at = time.monotonic() + self._retry_s
                        self._retry_s = min(self._retry_s * 2, 5.0)
                        logger.warning("lease reconnect failed: %s", exc)
                        continue
                try:
                    await self._cycle()
                except _CONNECTION_ERRORS as exc:
                    self._lost(f"cycle failed: {exc!r}")
                except Exception:
                    self.counters.errors += 1
                    logger.warning("lease cycle failed", exc_info=True)
            # at most one cycle per 50 ms, however often we are poked
            await asyncio.sleep(0.05)

    async def snapshot(self) -> Snapshot:
        conn, me = self._conn, self._pid
        if conn is None or me is None:
            raise ConnectionFailure("the lease connection is not open")
        rows = await conn.fetch(_SNAPSHOT, self.service, timeout=self._timeout)
        robots: list[str] = []
        holders: dict[str, int | None] = {}
        members: set[int] = set()
        for robot, pid in rows:
            if robot is None:
                members.add(pid)
            else:
                robots.append(robot)
                holders[robot] = pid
        return Snapshot(tuple(robots), holders, frozenset(members), me)

    async def _cycle(self) -> None:
        conn = self._conn
        if conn is None:
            return
        started = time.monotonic()
        view = await self.snapshot()
        self._confirmed_at = started
        self.counters.cycles += 1
        state = self._state
        # Robots whose row is gone: give the lock back. Robots whose lock is not ours any
        # more (it cannot happen while the connection lives; be safe): forget them.
        gone = [r for r in state.owned if r not in view.holders]
        stolen = [r for r in state.owned if r in view.holders and view.holders[r] != view.me]
        if stolen:
            logger.error("locks not held any more: %s", ",".join(sorted(stolen)))
        if gone or stolen:
            state.owned.difference_update(gone + stolen)
            self._changed(frozenset(), frozenset(gone + stolen))
            for robot in gone:
                await self._release(conn, robot, ROBOT_GONE)

        decision = decide(
            view, frozenset(state.owned), self.instance, state.pending, self.settle_cycles
        )
        state.pending = decision.pending
        state.members = decision.replicas
        state.share = decision.share

        if decision.release:
            state.owned.difference_update(decision.release)
            self._changed(frozenset(), frozenset(decision.release))  # stop acting first
            for robot in decision.release:
                await self._release(conn, robot, REBALANCE)
            log.event(
                logger,
                logging.INFO,
                "robots given back",
                service=self.service,
                robots=",".join(decision.release),
                replicas=decision.replicas,
                share="{}-{}".format(*decision.share),
                owned=len(state.owned),
            )

        gained: list[str] = []
        for robot in decision.acquire:
            if len(gained) >= decision.want:
                break
            try:
                lease_id = await conn.fetchval(
                    _ACQUIRE, self.service, robot, self.instance, timeout=self._timeout
                )
            except asyncpg.PostgresError as exc:
                if isinstance(exc, _CONNECTION_ERRORS):
                    raise
                logger.warning("could not lease %s: %s", robot, exc)  # e.g. robot just deleted
                continue
            if lease_id is not None:
                state.owned.add(robot)
                gained.append(robot)
                self.counters.acquired += 1
                self._notify(robot, int(lease_id))
        if gained:
            log.event(
                logger,
                logging.INFO,
                "robots leased",
                service=self.service,
                robots=",".join(gained),
                replicas=decision.replicas,
                share="{}-{}".format(*decision.share),
                owned=len(state.owned),
            )
            self._changed(frozenset(gained), frozenset())

    async def _release(self, conn: asyncpg.Connection, robot: str, reason: str) -> None:
        await conn.fetchval(_RELEASE, self.service, robot, reason, timeout=self._timeout)
        self.counters.released += 1
        self._notify(robot, None)

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


# -- reading ownership from outside (status tools, tests) -----------------------------------
_OWNERSHIP = f"""
WITH {_HELD}
SELECT r.robot_id, h.pid, l.instance
  FROM {keys.ROBOT} r
  LEFT JOIN held h ON h.k = {keys.LEASE_KEY_FN}(r.robot_id) AND h.mode = 'ExclusiveLock'
  LEFT JOIN {keys.ROBOT_LEASE} l ON l.service = $1 AND l.robot_id = r.robot_id
                                AND l.released_at IS NULL AND l.backend_pid = h.pid
 ORDER BY r.robot_id
"""
_REPLICAS = f"""
WITH {_HELD}
SELECT count(*) FROM held WHERE k = {keys.LEASE_MEMBER_KEY} AND mode = 'ShareLock'
"""
_HISTORY = f"""
SELECT robot_id, instance, acquired_at, released_at FROM {keys.ROBOT_LEASE}
 WHERE service = $1 ORDER BY robot_id, acquired_at, id
"""


async def ownership(conn: asyncpg.Connection, service: str) -> dict[str, str | None]:
    """Robot -> the instance of ``service`` that owns it now (None: nobody), as Postgres'
    locks say. An owner whose history row is not committed yet shows as ``pid:<backend>``."""
    out: dict[str, str | None] = {}
    for robot, pid, instance in await conn.fetch(_OWNERSHIP, service):
        out[robot] = None if pid is None else (instance or f"pid:{pid}")
    return out


async def live_replicas(conn: asyncpg.Connection, service: str) -> int:
    """How many replicas of ``service`` hold their membership lock now."""
    return int(await conn.fetchval(_REPLICAS, service))


async def history_overlaps(conn: asyncpg.Connection, service: str) -> list[str]:
    """Every pair of robot_lease rows of ``service`` whose tenures of one robot overlap
    (an open row followed by another, or a release after the next acquisition)."""
    problems = []
    previous: asyncpg.Record | None = None
    for row in await conn.fetch(_HISTORY, service):
        if previous is not None and previous["robot_id"] == row["robot_id"]:
            end = previous["released_at"]
            if end is None or end > row["acquired_at"]:
                problems.append(
                    f"{row['robot_id']}: {previous['instance']} held it until {end}, "
                    f"{row['instance']} took it at {row['acquired_at']}"
                )
        previous = row
    return problems

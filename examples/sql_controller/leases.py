"""Robot leases (CONTRACT.md, *Robot leases*): which robots this controller may act for.

Replicas of the ``controller`` family split the robots, whatever code each replica runs:
this example, the shipped controller, or one in another language. Postgres decides, and
nothing else:

- one dedicated connection (never a pooled one: a session lock must die with its owner),
  with ``idle_session_timeout`` so that Postgres frees our robots if we stop talking;
- on it, the membership lock ``(lease_key('controller'), 0)`` taken shared while we run;
- robot R is ours exactly while that connection holds ``(lease_key('controller'),
  lease_key(R))``, taken with ``robot_lease_acquire`` and given back with
  ``robot_lease_release`` (each followed by a ``pnav/db/robot_lease/{R}`` notification);
- every period, one read of ``robot_lease_holders('controller')`` (``robot`` and
  ``pg_locks``, counting only sessions of roles that may hold the controller's leases)
  gives the live replicas and the holder of every robot; we take free robots up to our fair
  share and give back what is above it once the excess has lasted two cycles (so ownership
  does not flap).

We stop acting for a robot *before* releasing it: :attr:`Leases.acting` is held by the
controller while it decides and writes, and a release first waits for it.

Two rules keep one controller per robot even when the lock connection dies in a way we
learn of late (Postgres ends the session, asyncpg gets the FATAL while idle and only fails
its next query, whatever exception type that is):

- we act only while the lock connection is open and our last successful read of
  ``pg_locks`` started less than 80 % of ``idle_session_timeout`` ago; *any* error from a
  query on that connection drops every robot at once, closes it, and we reconnect;
- a robot whose previous holder vanished (``robot_lease_acquire`` closed its row as
  ``holder gone``) is not acted on before 80 % of the timeout after that: the old holder's
  last confirmed read started before its session ended, so by then it has stopped trusting
  it. A robot given back cleanly (``rebalance``, ``shutdown``) is acted on at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import asyncpg

from examples.sql_controller.environment import SERVICE, Settings

logger = logging.getLogger("sql_controller.leases")

# Every robot with the backend holding its lock, then one row (robot NULL) per live replica:
# the contract's one read of pg_locks (migration 10), which ignores locks of sessions whose
# role may not hold the controller's leases.
_SNAPSHOT = "SELECT robot_id, pid FROM robot_lease_holders($1)"
# A robot deleted since the snapshot yields no row rather than a foreign-key error.
_ACQUIRE = "SELECT robot_lease_acquire($1, $2, $3) FROM robot WHERE robot_id = $2"
# Seconds still to wait before acting for robot $2: $3 after its newest "holder gone" end.
_TAKEOVER_WAIT = """
SELECT greatest(0.0, $3::float8
                     - extract(epoch FROM clock_timestamp() - max(released_at))::float8)
  FROM robot_lease
 WHERE service = $1 AND robot_id = $2 AND reason = 'holder gone'
   AND released_at > clock_timestamp() - make_interval(secs => $3::float8)
"""
Notify = Callable[[str, int | None], None]  # (robot, robot_lease id or None)


@dataclass(frozen=True)
class Plan:
    take: tuple[str, ...]  # free robots, best first
    want: int  # how many of them to take
    excess: int  # how many of ours are above the fair share


def affinity(instance: str, robot: str) -> int:
    """Replicas try free robots in different orders, so they rarely race for the same one."""
    return int.from_bytes(hashlib.sha256(f"{instance}/{robot}".encode()).digest()[:8], "big")


def plan(holders: Mapping[str, int | None], members: set[int], me: int, instance: str) -> Plan:
    """The contract's fair share: with R robots and N live replicas, hold floor(R/N) to
    ceil(R/N); take up to floor, up to ceil only when no replica is below floor; more than
    ceil is excess, and so is more than floor when another replica is below floor, nothing
    is free, and we are the richest (ties: the lowest backend pid gives)."""
    counts = dict.fromkeys(members | {me}, 0)
    for pid in holders.values():
        if pid in counts:
            counts[pid] += 1
    n = len(counts)
    low, high = len(holders) // n, -(-len(holders) // n)
    mine = counts[me]
    others_short = any(c < low for pid, c in counts.items() if pid != me)
    free = sorted(
        (r for r, pid in holders.items() if pid is None), key=lambda r: -affinity(instance, r)
    )
    want = max(0, min(len(free), (low if others_short else high) - mine))
    excess = mine - high if mine > high else 0
    if not excess and mine > low and others_short and not free:
        richest = max(counts.values())
        excess = int(mine == richest and me == min(p for p, c in counts.items() if c == richest))
    return Plan(tuple(free), want, excess)


class Leases:
    def __init__(self, settings: Settings, notify: Notify) -> None:
        self.settings = settings
        self.notify = notify
        self.acting = asyncio.Lock()  # held by the controller while it acts for our robots
        self._owned: set[str] = set()  # robots whose lock we hold
        self._ready_at: dict[str, float] = {}  # taken over from a vanished holder: act after
        self._conn: asyncpg.Connection | None = None
        self._me = 0
        self._confirmed = 0.0  # monotonic start of the last cycle that read our locks
        self._valid_s = 0.8 * settings.lease_timeout_s
        self._excess_cycles = 0
        self._failures = 0  # failed cycles or connects in a row
        self._poke = asyncio.Event()
        self._timeout = max(1.0, settings.lease_timeout_s / 2)

    def owned(self) -> frozenset[str]:
        """Our robots: none unless the lock connection is open and our view younger than
        80 % of the idle timeout (by then Postgres may have ended our session and handed
        them on); not those whose takeover wait runs."""
        conn = self._conn
        now = time.monotonic()
        if conn is None or conn.is_closed() or now - self._confirmed > self._valid_s:
            return frozenset()
        return frozenset(r for r in self._owned if self._ready_at.get(r, 0.0) <= now)

    def poke(self) -> None:
        """Revise now (a replica came or went, a robot was registered)."""
        self._poke.set()

    async def start(self) -> None:
        """Connect and take our share before the controller's first tick."""
        deadline = time.monotonic() + self.settings.db_wait_s
        while True:
            try:
                await self._connect()
                await self._cycle()
                return
            except Exception:
                self._drop_all("could not start")
                if time.monotonic() >= deadline:
                    raise
                await asyncio.sleep(0.2)

    async def run(self, stop: asyncio.Event) -> None:
        """Revise every period until ``stop``. Never ends on an error: whatever fails, we
        stop acting for every robot, close the lock connection and connect again."""
        while not stop.is_set():
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(self._nap()):
                    await self._poke.wait()
            self._poke.clear()
            if stop.is_set():
                return
            try:
                if self._conn is None:
                    await self._connect()
                await self._cycle()
                self._failures = 0
            except Exception as exc:
                self._failures += 1
                self._drop_all(f"lease cycle failed: {exc!r}")
            await asyncio.sleep(0.05)  # at most 20 cycles a second, however often poked

    def _nap(self) -> float:
        """A period; after failures in a row, longer (up to 5 s), so an outage is not
        hammered."""
        if self._failures <= 1:
            return self.settings.lease_period_s
        return min(self.settings.lease_period_s * 2.0 ** (self._failures - 1), 5.0)

    async def stop(self) -> None:
        """Give every robot back (reason ``shutdown``), leave, close the lock connection."""
        conn = self._conn
        if conn is None or conn.is_closed():
            self._drop_all("stopping")
            return
        try:
            await self._give_back(conn, set(self._owned), "shutdown")
            await conn.fetchval(
                "SELECT pg_advisory_unlock_shared(lease_key($1), 0)", SERVICE, timeout=self._timeout
            )
            await conn.close(timeout=self._timeout)
        except Exception:
            logger.warning("lease connection did not close cleanly", exc_info=True)
            conn.terminate()  # closing the session frees its locks anyway
        self._conn = None
        self._owned.clear()

    # -- internals ---------------------------------------------------------------------------
    async def _connect(self) -> None:
        conn = await asyncpg.connect(
            self.settings.database_url,
            timeout=self._timeout,
            server_settings={
                "application_name": f"pnav-lease {SERVICE}/{self.settings.instance}"[:63]
            },
        )
        try:
            ms = int(self.settings.lease_timeout_s * 1000)
            await conn.execute(f"SET idle_session_timeout = {ms}", timeout=self._timeout)
            self._me = int(await conn.fetchval("SELECT pg_backend_pid()", timeout=self._timeout))
            joined = await conn.fetchval(
                "SELECT pg_try_advisory_lock_shared(lease_key($1), 0)",
                SERVICE,
                timeout=self._timeout,
            )
            if not joined:
                raise ConnectionError("the controller membership lock is held exclusively")
        except BaseException:
            conn.terminate()
            raise
        conn.add_termination_listener(self._on_closed)
        self._conn = conn
        logger.info("lease connection open, backend pid %d", self._me)

    def _on_closed(self, conn: asyncpg.Connection) -> None:
        if conn is self._conn:
            self._drop_all("the lock connection closed")

    def _drop_all(self, why: str) -> None:
        """The connection is gone or unusable, and our locks with it (or about to be, once
        we close it): stop acting for every robot now."""
        if self._owned:
            logger.warning("%s: no longer acting for %s", why, ",".join(sorted(self._owned)))
        elif self._conn is not None:
            logger.warning("%s", why)
        self._owned.clear()
        self._ready_at.clear()
        self._confirmed = 0.0
        conn, self._conn = self._conn, None
        if conn is not None and not conn.is_closed():
            conn.terminate()

    async def _cycle(self) -> None:
        conn = self._conn
        if conn is None:
            return
        started = time.monotonic()
        holders: dict[str, int | None] = {}
        members: set[int] = set()
        for robot, pid in await conn.fetch(_SNAPSHOT, SERVICE, timeout=self._timeout):
            if robot is None:
                members.add(pid)
            else:
                holders[robot] = pid
        self._confirmed = started
        # pg_locks is the truth; a robot whose row was deleted still has our lock: free it.
        gone = {r for r in self._owned if r not in holders}
        self._owned = {r for r, pid in holders.items() if pid == self._me}
        self._ready_at = {r: t for r, t in self._ready_at.items() if r in self._owned}
        await self._give_back(conn, gone, "robot gone")

        decision = plan(holders, members, self._me, self.settings.instance)
        self._excess_cycles = self._excess_cycles + 1 if decision.excess else 0
        if self._excess_cycles >= 2:  # hysteresis: an excess must last two cycles
            self._excess_cycles = 0
            ours = sorted(self._owned, key=lambda r: affinity(self.settings.instance, r))
            await self._give_back(conn, set(ours[: decision.excess]), "rebalance")
        taken: list[str] = []
        for robot in decision.take:
            if len(taken) >= decision.want:
                break
            if await self._take(conn, robot):
                taken.append(robot)
        if taken:
            logger.info("leased %s (replicas %d)", ",".join(taken), len(members | {self._me}))

    async def _take(self, conn: asyncpg.Connection, robot: str) -> bool:
        lease_id = await conn.fetchval(
            _ACQUIRE, SERVICE, robot, self.settings.instance, timeout=self._timeout
        )
        if lease_id is None:  # another replica was quicker (or the robot is gone)
            return False
        wait_s = await conn.fetchval(
            _TAKEOVER_WAIT, SERVICE, robot, self._valid_s, timeout=self._timeout
        )
        self._owned.add(robot)
        if wait_s:
            self._ready_at[robot] = time.monotonic() + float(wait_s)
            logger.info("took %s over from a vanished holder: acting in %.1f s", robot, wait_s)
        self.notify(robot, int(lease_id))
        return True

    async def _give_back(self, conn: asyncpg.Connection, robots: set[str], reason: str) -> None:
        if not robots:
            return
        self._owned -= robots
        async with self.acting:  # a tick under way for them finishes first; none starts
            pass
        for robot in sorted(robots):
            await conn.fetchval(
                "SELECT robot_lease_release($1, $2, $3)",
                SERVICE,
                robot,
                reason,
                timeout=self._timeout,
            )
            self._ready_at.pop(robot, None)
            self.notify(robot, None)
        logger.info("gave back %s (%s)", ",".join(sorted(robots)), reason)

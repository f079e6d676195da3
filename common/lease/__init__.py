"""Robot leases: replicas of one scenario service split the robots between them.

The protocol is the contract's (CONTRACT.md, *Robot leases*; migration 2); this package is
its Python side: :mod:`~common.lease.share` (the arithmetic, pure), :mod:`~common.lease.sql`,
:mod:`~common.lease.session` (the lock connection), :mod:`~common.lease.manager`
(:class:`LeaseManager`) and :mod:`~common.lease.status` (reading ownership from outside).

- A replica owns robot R of service S exactly while its **one dedicated Postgres connection**
  (never a pooled one: a pooled connection's session locks would leak to whoever borrows it
  next) holds the session-level advisory lock ``(lease_key(S), lease_key(R))``. Postgres is
  the only judge of who owns what; there is no election, no heartbeat table, no consensus of
  our own.
- It counts as a live replica while that connection holds ``(lease_key(S), 0)`` shared. So
  the number of replicas comes from the same place as the locks and dies with them.
  (Zenoh liveliness tokens would be a second, independent view of who is alive that can
  disagree with the locks for seconds; they only *hint* that it is worth looking again now:
  :meth:`LeaseManager.poke`.)
- Every ``period_s`` a cycle reads the robots and ``pg_locks`` in one query, computes the
  fair share (:func:`fair_share`, :func:`decide`), takes free robots with
  ``robot_lease_acquire`` and gives back robots above the share once the excess has lasted
  ``settle_cycles`` cycles (hysteresis).

When ownership is trusted
-------------------------
The lock connection runs with ``idle_session_timeout`` = ``timeout_s``. A replica acts for
its robots only while (a) its lock connection is open (``is_closed()`` is false) and (b)
its last cycle whose read of ``pg_locks`` succeeded *started* less than
``valid_s = 0.8 * timeout_s`` ago. Any exception from any query on the lock connection
means the connection is unusable, whatever its type: every robot is dropped at once, the
connection is closed, and the replica reconnects (:mod:`~common.lease.session` says why no
list of exception types can be trusted for this).

The takeover wait
-----------------
Postgres frees a session's locks the instant the session ends, but the replica may learn
of it only later: asyncpg can receive the FATAL while idle and keep its socket open, so the
loss shows only when the next query fails (one period later), or never, if the replica is
hung. A replica that takes over such a robot at once would act beside the old owner.
So: let ``E`` be when the old session ended and ``c`` the start of the old owner's last
confirmed cycle. That cycle's read ran on the session, so ``c < E``, and the old owner
stops trusting at ``c + valid_s < E + valid_s``. The newcomer's ``robot_lease_acquire``
succeeds at some ``A >= E`` (the lock was free); it closes the old owner's open row with
reason ``holder gone`` and ``released_at = A``. The newcomer then does not act for the
robot before ``A + valid_s`` (``takeover_wait_s = valid_s``: 4 s with the default 5 s
timeout, 1.6 s with the tests' 2 s), which is after ``E + valid_s``: the two never act
at once, by construction, not by timing luck. (Clocks: the old owner measures on its
monotonic clock, the newcomer on its own from a moment no earlier than ``A``; rates differ
by parts per million.)

Only unclean losses wait, told apart by the history: a live replica that gives a robot back
(``rebalance``, ``shutdown``, ``robot gone``) has stopped acting for it, and waited for the
engine's activation under way then to end (the *hand-over*, :mod:`~common.lease.cycle`: a
rule of that activation may have looked at ``owns`` before and still be writing for the
robot), *before* its ``robot_lease_release`` closes the row and then unlocks, so the next
holder may act at once and reads every row the last one wrote. A replica that finds its own
connection lost closes its old rows as ``connection lost`` only after it has dropped every
robot, so those are clean too. Only a row closed as ``holder gone`` by
``robot_lease_acquire`` means the holder vanished without saying so. The wait is computed by
the server after each acquisition as ``valid_s`` after the newest ``holder gone`` release of
that robot (so a robot passed on cleanly by a replica that was still waiting for it keeps
the first wait), and measured from the answer.
All replicas of a service must run with the same ``timeout_s``.

Who can take or block a lease
-----------------------------
The keys are public (``lease_key`` is sha256 of the names), so the locks themselves must be
out of reach. Two rules (migration 10; CONTRACT.md, *Robot leases*):

- **Taking an advisory lock is a privilege.** The superuser who sets the database up
  (:func:`common.contract.roles.bootstrap`: ``pnav up``, ``pnav migrate --roles``) revokes
  EXECUTE on every catalog function that takes one (``pg_advisory_lock``, ``_shared``,
  ``_xact``, ``pg_try_*``) from PUBLIC, and grants it to the roles CONTRACT.md lets INSERT
  into ``robot_lease`` (the services that hold leases) and to ``pnav_owner`` (the
  migrations' lock). The people's role (``pnav_user``) cannot take any advisory lock, so it
  can neither hold a robot nor join as a replica; ``robot_lease_acquire`` fails for it on
  that privilege; it may not write ``robot_lease``, lock its rows (``FOR UPDATE``/``SHARE``
  need UPDATE) or lock the table beyond ACCESS SHARE (which only DDL waits for), nor end or
  cancel another role's session. Locks are taken with ``pg_try_*`` only, so nothing of ours
  ever waits on a lock anyway.
- **Another role's lock is ignored, not obeyed.** The cycle's one read of ``pg_locks`` is
  the server's ``robot_lease_holders(S)``, which counts a lock only when its session's role
  may hold leases of S (INSERT on ``robot_lease``, and for a ``pnav_<family>`` role the
  family S, as row security has it). A planner holding the controller's membership lock is
  not a controller replica; nobody gives a robot back for it.

Residual risks: a superuser (and the tables' owner) can do anything, this included; a
database not set up by a superuser (no roles: every process connects as one account) has no
privilege to withhold, so every client there can take leases; a service role may take
another family's robot locks (it holds the lock privilege for its own leases): it is not
counted as an owner or a replica, but the robot stays unowned while it holds the lock
(the services trust each other's roles as they trust each other's code); a client that
exhausts Postgres' connections or shared lock table stalls every service alike.

:class:`~common.service.ScenarioService` starts a :class:`LeaseManager` before the engine's
first activation and exposes ``owns(robot_id)``.
"""

from __future__ import annotations

from common.lease.cycle import LeaseCounters
from common.lease.manager import TRUST_FRACTION, LeaseManager, Notify, OwnershipListener
from common.lease.share import Decision, Snapshot, affinity, decide, fair_share, lease_key
from common.lease.sql import CONNECTION_LOST, HOLDER_GONE, REBALANCE, ROBOT_GONE, SHUTDOWN
from common.lease.status import history_overlaps, live_replicas, ownership

__all__ = [
    "CONNECTION_LOST",
    "HOLDER_GONE",
    "REBALANCE",
    "ROBOT_GONE",
    "SHUTDOWN",
    "TRUST_FRACTION",
    "Decision",
    "LeaseCounters",
    "LeaseManager",
    "Notify",
    "OwnershipListener",
    "Snapshot",
    "affinity",
    "decide",
    "fair_share",
    "history_overlaps",
    "lease_key",
    "live_replicas",
    "ownership",
]

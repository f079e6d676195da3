"""The SQL of the lease protocol (CONTRACT.md, *Robot leases*; migration 2)."""

from __future__ import annotations

from common.contract import keys

# Reasons written to robot_lease.reason.
REBALANCE = "rebalance"
SHUTDOWN = "shutdown"
CONNECTION_LOST = "connection lost"
ROBOT_GONE = "robot gone"
HOLDER_GONE = "holder gone"  # written by robot_lease_acquire for a holder that vanished

# One read per cycle: every robot with the backend holding its lock, then the live replicas
# (robot NULL). The server function reads pg_locks once and ignores a lock whose session's
# role may not hold leases of $1 (migration 10): nobody else's lock is obeyed.
SNAPSHOT = f"SELECT robot_id, pid FROM {keys.LEASE_HOLDERS_FN}($1)"
JOIN = f"SELECT pg_try_advisory_lock_shared({keys.LEASE_KEY_FN}($1), {keys.LEASE_MEMBER_KEY})"
LEAVE = f"SELECT pg_advisory_unlock_shared({keys.LEASE_KEY_FN}($1), {keys.LEASE_MEMBER_KEY})"
# Only for a robot that still has its row: one deleted since the snapshot yields no row
# instead of a foreign-key error (any error on the lock connection drops every robot).
ACQUIRE = f"""
SELECT {keys.LEASE_ACQUIRE_FN}($1, $2, $3) FROM {keys.ROBOT} WHERE robot_id = $2
"""
RELEASE = f"SELECT {keys.LEASE_RELEASE_FN}($1, $2, $3)"
# Seconds still to wait before acting for robot $2 just taken: $3 (the takeover wait) after
# the newest tenure of it that ended with its holder gone, by the server's clock, which
# wrote that time. See the takeover wait in common/lease/__init__.py.
TAKEOVER_WAIT = f"""
SELECT greatest(0.0, $3::float8
                     - extract(epoch FROM clock_timestamp() - max(released_at))::float8)
  FROM {keys.ROBOT_LEASE}
 WHERE service = $1 AND robot_id = $2 AND reason = '{HOLDER_GONE}'
   AND released_at > clock_timestamp() - make_interval(secs => $3::float8)
"""
# After a reconnect: end what an earlier session of ours left (if it is still there, it is
# told to go first, so its locks cannot outlive it for the idle timeout).
END_OLD_SESSION = """
SELECT pg_terminate_backend(pid) FROM pg_stat_activity
 WHERE pid = $1 AND application_name = $2 AND pid <> pg_backend_pid()
"""
CLOSE_MINE = f"""
UPDATE {keys.ROBOT_LEASE} SET released_at = clock_timestamp(), reason = $2
 WHERE service = $1 AND backend_pid = pg_backend_pid() AND released_at IS NULL
"""
CLOSE_OLD_ROWS = f"""
UPDATE {keys.ROBOT_LEASE} SET released_at = clock_timestamp(), reason = $4
 WHERE service = $1 AND instance = $2 AND backend_pid = $3 AND released_at IS NULL
RETURNING robot_id
"""

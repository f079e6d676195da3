"""Least privilege in Postgres: one role per service, GRANTs from CONTRACT.md's *Roles* table.

:func:`bootstrap` is run by whoever sets a database up with a privileged account (``pnav up``
on its embedded server, ``pnav migrate --roles`` in compose): it creates the roles, makes
``pnav_owner`` own every table and function, applies the migrations *as* ``pnav_owner``, and
grants each login role what common.contract.grants reads from CONTRACT.md, revoking what the
table no longer grants. It is idempotent and run on every start, so a new migration's table
gets its grants at once. It also keeps advisory locks for the lease holders: EXECUTE on the
catalog functions that take one is revoked from PUBLIC and granted to the roles that may
INSERT into robot_lease and to pnav_owner (CONTRACT.md, *Roles*: robot ownership is such a
lock, and no people's client may take or block one).

Roles are cluster-wide, GRANTs per database: several databases of one server share the roles
(and their passwords) and each gets its own grants. Role creation is not a migration for that
reason, and because passwords are per deployment, not part of the contract.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from urllib.parse import quote, urlsplit, urlunsplit

import asyncpg

from common.contract.grants import (
    LOGIN_ROLES,
    OWNER,
    USER,
    Grant,
    contract_grants,
    lease_holders,
    role_name,
)
from common.contract.migrate import apply_migrations
from common.errors import MigrationError, UsageError

log = logging.getLogger("pnav.roles")

_ATTRIBUTES = "NOSUPERUSER NOCREATEDB NOCREATEROLE NOREPLICATION NOBYPASSRLS"
# Races with another database of the same server doing the same at the same moment.
_RACES = (asyncpg.DuplicateObjectError, asyncpg.UniqueViolationError, asyncpg.InternalServerError)
_SEQUENCES_OF = """
SELECT s.relname FROM pg_class s
  JOIN pg_depend d ON d.classid = 'pg_class'::regclass AND d.objid = s.oid AND d.deptype = 'a'
  JOIN pg_class t ON t.oid = d.refobjid
 WHERE s.relkind = 'S' AND t.relname = $1 AND t.relnamespace = 'public'::regnamespace
"""
_OWNED_ELSEWHERE = """
SELECT 'TABLE ' || quote_ident(c.relname) FROM pg_class c
 WHERE c.relnamespace = 'public'::regnamespace AND c.relkind IN ('r', 'p', 'v')
   AND pg_get_userbyid(c.relowner) <> $1
UNION ALL
SELECT 'FUNCTION ' || p.oid::regprocedure::text FROM pg_proc p
 WHERE p.pronamespace = 'public'::regnamespace AND pg_get_userbyid(p.proowner) <> $1
   AND NOT EXISTS (SELECT 1 FROM pg_depend d WHERE d.classid = 'pg_proc'::regclass
                   AND d.objid = p.oid AND d.deptype = 'e')
"""

# The people's sessions (the CLI, dashboards, psql as pnav_user) may hold a transaction open,
# idle, this long; then the server ends the session. A people's role may UPDATE some tables,
# so it may lock them: a transaction left open (a crashed tool, a person at a prompt) would
# hold its locks for ever. The shipped tools never hold one for more than a few statements.
# A role's default only: a session may SET it otherwise, so the services bound their own
# lock waits as well (common.db.lock_settings; CONTRACT.md, *Roles*).
PEOPLE_IDLE_IN_TRANSACTION = "5s"

# Every catalog function that takes an advisory lock (session or transaction, shared or not,
# waiting or trying), whatever overloads this Postgres has.
_ADVISORY_LOCKS = """
SELECT p.oid::regprocedure::text FROM pg_proc p
 WHERE p.pronamespace = 'pg_catalog'::regnamespace
   AND p.proname ~ '^pg_(try_)?advisory_(xact_)?lock(_shared)?$'
 ORDER BY 1
"""


class RolesUnavailable(UsageError):
    """The account given cannot set the roles up: it is not a superuser."""


def role_url(url: str, role: str, password: str | None) -> str:
    """``url`` with its user (and password) replaced by ``role``'s."""
    parts = urlsplit(url)
    host = parts.netloc.rpartition("@")[2]
    auth = quote(role, safe="")
    if password is not None:
        auth += ":" + quote(password, safe="")
    return urlunsplit(parts._replace(netloc=f"{auth}@{host}"))


async def is_superuser(conn: asyncpg.Connection) -> bool:
    return bool(await conn.fetchval("SELECT rolsuper FROM pg_roles WHERE rolname = current_user"))


async def _retry_race(conn: asyncpg.Connection, sql: str) -> None:
    for attempt in range(5):
        try:
            await conn.execute(sql)
            return
        except _RACES:
            if attempt == 4:
                raise


async def ensure_roles(conn: asyncpg.Connection, passwords: Mapping[str, str]) -> None:
    """Create the owner and every login role if missing; (re)set their attributes (and the
    people's idle-in-transaction bound), and the password of each role (short name)
    ``passwords`` names. A role not named keeps its password (none, on a server that trusts
    its local connections)."""
    for short in (OWNER, *LOGIN_ROLES):
        name = role_name(short)
        login = "NOLOGIN" if short == OWNER else "LOGIN"
        exists = await conn.fetchval("SELECT 1 FROM pg_roles WHERE rolname = $1", name)
        if not exists:
            try:
                await conn.execute(f"CREATE ROLE {name} {login} {_ATTRIBUTES}")
            except _RACES:
                pass  # created meanwhile for another database of this server
        await _retry_race(conn, f"ALTER ROLE {name} {login} {_ATTRIBUTES}")
        if short == USER:
            await _retry_race(
                conn,
                f"ALTER ROLE {name} SET idle_in_transaction_session_timeout "
                f"= '{PEOPLE_IDLE_IN_TRANSACTION}'",
            )
        password = passwords.get(short)
        if password is not None:
            sql = await conn.fetchval(
                "SELECT format('ALTER ROLE %I PASSWORD %L', $1::text, $2::text)", name, password
            )
            await _retry_race(conn, sql)


async def _take_ownership(conn: asyncpg.Connection) -> None:
    """Make pnav_owner own the public schema's tables and functions (a database migrated
    before roles existed has them owned by whoever applied the migrations)."""
    owner = role_name(OWNER)
    await conn.execute(f"GRANT USAGE, CREATE ON SCHEMA public TO {owner}")
    for (what,) in await conn.fetch(_OWNED_ELSEWHERE, owner):
        await conn.execute(f"ALTER {what} OWNER TO {owner}")


async def apply_grants(conn: asyncpg.Connection, grants: tuple[Grant, ...] | None = None) -> int:
    """Revoke every login role's privileges on the public schema's tables, sequences and
    functions, then grant SELECT on every table and what ``grants`` say, in one transaction
    (a service never sees a moment with no grant). Returns the number of GRANTs run."""
    grants = contract_grants() if grants is None else grants
    roles = ", ".join(role_name(r) for r in LOGIN_ROLES)
    statements = [
        f"REVOKE ALL ON ALL TABLES IN SCHEMA public FROM {roles}",
        f"REVOKE ALL ON ALL SEQUENCES IN SCHEMA public FROM {roles}",
        f"REVOKE ALL ON ALL FUNCTIONS IN SCHEMA public FROM {roles}",
        f"GRANT USAGE ON SCHEMA public TO {roles}",
        f"GRANT SELECT ON ALL TABLES IN SCHEMA public TO {roles}",
    ]
    for grant in grants:
        if grant.role == OWNER:
            continue  # the owner holds every privilege already
        statements.append(grant.sql())
        if grant.privilege == "INSERT":
            for (sequence,) in await conn.fetch(_SEQUENCES_OF, grant.name):
                # UPDATE: setval, for a writer that restores its own rows after a crash
                # with their ids (services/bridge/replay.py)
                statements.append(
                    f"GRANT USAGE, UPDATE ON SEQUENCE {sequence} TO {role_name(grant.role)}"
                )
    statements += await _advisory_lock_grants(conn, grants)
    async with conn.transaction():
        for sql in statements:
            try:
                await conn.execute(sql)
            except asyncpg.PostgresError as exc:
                raise MigrationError(f"{sql}: {exc}") from exc
    return len(statements)


async def _advisory_lock_grants(conn: asyncpg.Connection, grants: tuple[Grant, ...]) -> list[str]:
    """Advisory locks for the lease holders only: EXECUTE on every function that takes one is
    revoked from PUBLIC (so from every role, people's included) and granted to the roles that
    may hold robot leases and to the owner (the migrations' lock). Robot ownership is such a
    lock (CONTRACT.md, *Robot leases*); a role that could take one could block a robot, or
    count as a replica and be given robots. Catalog privileges are per database."""
    holders = ", ".join(role_name(r) for r in (OWNER, *lease_holders(grants)))
    others = ", ".join(["PUBLIC", *(role_name(r) for r in LOGIN_ROLES)])
    statements: list[str] = []
    for (function,) in await conn.fetch(_ADVISORY_LOCKS):
        statements.append(f"REVOKE EXECUTE ON FUNCTION {function} FROM {others}")
        statements.append(f"GRANT EXECUTE ON FUNCTION {function} TO {holders}")
    return statements


async def bootstrap(
    conn: asyncpg.Connection, passwords: Mapping[str, str] | None = None
) -> list[int]:
    """Set the database up with least privilege (see the module's docstring); return the
    migrations applied now. ``conn`` must be a superuser's: it hands objects to pnav_owner."""
    if not await is_superuser(conn):
        user = await conn.fetchval("SELECT current_user")
        raise RolesUnavailable(
            f"Postgres user {user!r} is not a superuser: it cannot create the service roles "
            "and hand the tables to pnav_owner (connect as the server's bootstrap superuser)"
        )
    await ensure_roles(conn, passwords or {})
    await _take_ownership(conn)
    await conn.execute(f"SET ROLE {role_name(OWNER)}")
    try:
        applied = await apply_migrations(conn)
    finally:
        await conn.execute("RESET ROLE")
    await _take_ownership(conn)  # objects a migration created as someone else (none shipped)
    await apply_grants(conn)
    return applied

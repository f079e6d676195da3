"""Least privilege: each role writes exactly what CONTRACT.md's *Roles* table grants it.

The database is set up as ``pnav up`` and ``pnav migrate --roles`` set it up
(common.contract.roles.bootstrap), then the test connects as every login role and tries
INSERT, UPDATE of each column, DELETE and SELECT on every table of the contract, and EXECUTE
on its functions: a privilege the table grants must get past the privilege check, every
other must fail with ``permission denied`` (SQLSTATE 42501).
"""

from __future__ import annotations

import uuid
from collections.abc import AsyncIterator

import asyncpg
import pytest

from common.config import ServiceConfig, ZenohSettings
from common.contract import grants as g
from common.contract.migrate import apply_migrations
from common.contract.roles import RolesUnavailable, bootstrap, role_url
from common.runtime import Runtime
from pnav.run.embedded_postgres import EmbeddedPostgres


@pytest.fixture
async def admin(empty_db_url: str) -> AsyncIterator[asyncpg.Connection]:
    conn = await asyncpg.connect(empty_db_url)
    try:
        await bootstrap(conn)
        yield conn
    finally:
        await conn.close()


async def _columns(conn: asyncpg.Connection) -> dict[str, list[str]]:
    rows = await conn.fetch(
        "SELECT table_name, column_name FROM information_schema.columns "
        "WHERE table_schema = 'public' ORDER BY table_name, ordinal_position"
    )
    out: dict[str, list[str]] = {}
    for row in rows:
        out.setdefault(row["table_name"], []).append(row["column_name"])
    return out


async def _permitted(conn: asyncpg.Connection, sql: str) -> bool:
    """Whether ``sql`` gets past the privilege check (it is rolled back either way): a
    constraint it then breaks (DEFAULT VALUES leaves NOT NULL columns empty) counts as
    permitted; ``permission denied`` as refused; anything else is a failure of the test."""
    tx = conn.transaction()
    await tx.start()
    try:
        await conn.execute(sql)
        return True
    except asyncpg.InsufficientPrivilegeError as exc:
        # row security (robot_lease, engine_stats: a row of one's own family only) is checked
        # after the GRANT: its refusal of a DEFAULT VALUES row means the GRANT let it through
        return "row-level security" in str(exc)
    except asyncpg.IntegrityConstraintViolationError:
        return True
    finally:
        await tx.rollback()


def _expected(table: str, role: str, privilege: str, column: str | None = None) -> bool:
    for grant in g.role_grants(role):
        if grant.name != table or grant.privilege != privilege:
            continue
        if column is None or not grant.columns or column in grant.columns:
            return True
    return False


async def test_every_table_of_the_contract_has_a_writer_in_the_roles_table(
    admin: asyncpg.Connection,
) -> None:
    tables = set(await _columns(admin))
    granted = {grant.name for grant in g.contract_grants() if not grant.is_function}
    assert tables - granted == set(), "tables CONTRACT.md's Roles table names no writer of"
    assert granted - tables == set(), "the Roles table names tables the contract lacks"


async def test_each_role_writes_exactly_its_documented_tables(
    admin: asyncpg.Connection, empty_db_url: str
) -> None:
    columns = await _columns(admin)
    wrong: list[str] = []
    for role in g.LOGIN_ROLES:
        conn = await asyncpg.connect(role_url(empty_db_url, g.role_name(role), None))
        try:
            for table, cols in columns.items():
                assert await _permitted(conn, f"SELECT * FROM {table} LIMIT 0"), (role, table)
                checks: list[tuple[str, str | None, str]] = [
                    ("INSERT", None, f"INSERT INTO {table} DEFAULT VALUES")
                ]
                checks += [("UPDATE", c, f"UPDATE {table} SET {c} = {c} WHERE false") for c in cols]
                checks.append(("DELETE", None, f"DELETE FROM {table} WHERE false"))
                for privilege, column, sql in checks:
                    expected = _expected(table, role, privilege, column)
                    if await _permitted(conn, sql) != expected:
                        verdict = "allowed" if expected else "refused"
                        wrong.append(f"{g.role_name(role)}: {sql} should be {verdict}")
        finally:
            await conn.close()
    assert wrong == []


async def test_only_the_granted_roles_may_prune_and_pruning_reaches_every_retained_table(
    admin: asyncpg.Connection, empty_db_url: str
) -> None:
    # the bridge prunes planned_path, which only the planner writes: SECURITY DEFINER
    await admin.execute("INSERT INTO robot (robot_id) VALUES ('r1')")
    await admin.execute("UPDATE retention_policy SET keep_rows_per_robot = 1")
    planner = await asyncpg.connect(role_url(empty_db_url, "pnav_planner", None))
    bridge = await asyncpg.connect(role_url(empty_db_url, "pnav_bridge", None))
    try:
        for stamp in (1.0, 2.0, 3.0):
            await planner.execute(
                "INSERT INTO planned_path (robot_id, stamp, target, xs, ys, length_m) "
                "VALUES ('r1', $1, 'none', '{}', '{}', 0)",
                stamp,
            )
        with pytest.raises(asyncpg.InsufficientPrivilegeError):
            await planner.fetchval("SELECT prune_sensor_rows()")
        with pytest.raises(asyncpg.InsufficientPrivilegeError):
            await bridge.execute("DELETE FROM planned_path")
        assert await bridge.fetchval("SELECT prune_sensor_rows()") == 2
        assert await admin.fetchval("SELECT array_agg(stamp) FROM planned_path") == [3.0]
    finally:
        await planner.close()
        await bridge.close()


async def test_no_role_of_the_stack_is_privileged_and_the_owner_owns_everything(
    admin: asyncpg.Connection,
) -> None:
    rows = await admin.fetch(
        "SELECT rolname, rolsuper, rolcreaterole, rolcreatedb, rolbypassrls, rolreplication, "
        "rolcanlogin FROM pg_roles WHERE rolname LIKE 'pnav\\_%'"
    )
    roles = {r["rolname"]: r for r in rows}
    assert set(roles) >= {g.role_name(r) for r in (g.OWNER, *g.LOGIN_ROLES)}
    for name, row in roles.items():
        assert not any(row[k] for k in ("rolsuper", "rolcreaterole", "rolcreatedb")), name
        assert not row["rolbypassrls"] and not row["rolreplication"], name
        assert row["rolcanlogin"] == (name != "pnav_owner"), name
    owners = await admin.fetch(
        "SELECT c.relname, pg_get_userbyid(c.relowner) AS owner FROM pg_class c "
        "WHERE c.relnamespace = 'public'::regnamespace AND c.relkind IN ('r', 'S')"
    )
    assert {r["relname"]: r["owner"] for r in owners if r["owner"] != "pnav_owner"} == {}


async def test_a_database_migrated_before_roles_existed_is_handed_over_and_migrates_on(
    empty_db_url: str,
) -> None:
    conn = await asyncpg.connect(empty_db_url)
    try:
        await apply_migrations(conn)  # as the superuser, as every release before roles did
        assert (
            await conn.fetchval(
                "SELECT pg_get_userbyid(relowner) FROM pg_class WHERE relname = 'goal'"
            )
            == "postgres"
        )
        assert await bootstrap(conn) == []  # idempotent: nothing left to apply
        await bootstrap(conn)
        owner = await conn.fetchval(
            "SELECT pg_get_userbyid(proowner) FROM pg_proc WHERE proname = 'prune_sensor_rows'"
        )
        assert owner == "pnav_owner"
        user = await asyncpg.connect(role_url(empty_db_url, "pnav_user", None))
        try:
            await conn.execute("INSERT INTO robot (robot_id) VALUES ('r1')")
            goal = await user.fetchval(
                "INSERT INTO goal (robot_id, x, y) VALUES ('r1', 1, 2) RETURNING id"
            )
            assert goal == 1
        finally:
            await user.close()
    finally:
        await conn.close()


def test_role_url_replaces_the_user_and_quotes_the_password() -> None:
    url = "postgresql://postgres:@/postgres?host=/tmp/pnav-pg-x"
    assert (
        role_url(url, "pnav_bridge", None)
        == "postgresql://pnav_bridge@/postgres?host=/tmp/pnav-pg-x"
    )
    assert (
        role_url("postgresql://a:b@db:5432/pnav", "pnav_user", "p@ss/w:rd")
        == "postgresql://pnav_user:p%40ss%2Fw%3Ard@db:5432/pnav"
    )


async def test_a_service_writes_leases_and_statistics_only_under_its_own_name(
    admin: asyncpg.Connection, empty_db_url: str
) -> None:
    await admin.execute("INSERT INTO robot (robot_id) VALUES ('r1'), ('r2')")
    planner = await asyncpg.connect(role_url(empty_db_url, "pnav_planner", None))
    controller = await asyncpg.connect(role_url(empty_db_url, "pnav_controller", None))
    try:
        # through the contract's functions, as every replica takes and gives back a robot
        assert await controller.fetchval("SELECT robot_lease_acquire('controller', 'r1', 'c-1')")
        with pytest.raises(asyncpg.InsufficientPrivilegeError, match="row-level security"):
            await planner.fetchval("SELECT robot_lease_acquire('controller', 'r2', 'p-1')")
        # the planner cannot close the controller's tenure: the row is not its to change
        closed = await planner.execute(
            "UPDATE robot_lease SET released_at = clock_timestamp(), reason = 'forged' "
            "WHERE service = 'controller'"
        )
        assert closed == "UPDATE 0"
        assert await planner.fetchval("SELECT count(*) FROM robot_lease") == 1  # it reads it
        assert await controller.fetchval("SELECT robot_lease_release('controller', 'r1', 'x')")
        stats = "INSERT INTO engine_stats (service, instance, rule_type) VALUES ($1, 'i', 'R')"
        await planner.execute(stats, "planner")
        with pytest.raises(asyncpg.InsufficientPrivilegeError, match="row-level security"):
            await planner.execute(stats, "controller")
        assert await controller.execute("UPDATE engine_stats SET executed = 9") == "UPDATE 0"
    finally:
        await planner.close()
        await controller.close()


async def test_the_cli_drives_a_robot_as_pnav_user_and_a_service_role_cannot(
    admin: asyncpg.Connection, empty_db_url: str, zenoh_settings: ZenohSettings
) -> None:
    from pnav.cli import stack_commands

    await admin.execute("INSERT INTO robot (robot_id) VALUES ('r1')")

    async def cli(role: str) -> Runtime:
        url = role_url(empty_db_url, g.role_name(role), None)
        return await Runtime.open(
            ServiceConfig(service="cli", database_url=url, zenoh=zenoh_settings)
        )

    people = await cli(g.USER)
    try:
        first = await stack_commands.set_goal(people, "r1", 1.0, 2.0)
        second = await stack_commands.set_goal(people, "r1", 3.0, 4.0)  # supersedes the first
        assert await stack_commands.cancel_goal(people, "r1") == second
        status, reason = await stack_commands.send_user_command(
            people, "r1", "SET_STRATEGY", "IDLE", 0.1
        )
        assert (status, reason) == ("pending", "no answer from the strategy service within 0 s")
        goals = await admin.fetch("SELECT id, status FROM goal ORDER BY id")
        assert [tuple(r) for r in goals] == [(first, "superseded"), (second, "cancelled")]
    finally:
        await people.close()
    planner = await cli("planner")
    try:
        with pytest.raises(asyncpg.InsufficientPrivilegeError):
            await stack_commands.set_goal(planner, "r1", 1.0, 2.0)  # the planner never sets goals
    finally:
        await planner.close()


async def test_a_stack_given_a_plain_account_migrates_and_runs_everything_as_it(
    pg: EmbeddedPostgres, caplog: pytest.LogCaptureFixture
) -> None:
    from pnav.run.local_stack import _set_up_roles

    name = f"t_plain_{uuid.uuid4().hex[:8]}"
    pg._server.psql(f"CREATE ROLE {name} LOGIN; CREATE DATABASE {name} OWNER {name};")
    url = role_url(pg.dsn(name), name, None)
    conn = await asyncpg.connect(url)
    try:
        with pytest.raises(RolesUnavailable, match="not a superuser"):
            await bootstrap(conn)
        assert await _set_up_roles(conn, url) == {}  # every service: the account given
        assert await conn.fetchval("SELECT max(version) FROM schema_version") >= 7
    finally:
        await conn.close()
    assert "is not a superuser: every service connects as it" in caplog.text

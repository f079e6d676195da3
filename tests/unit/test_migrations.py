"""The contract's migrations on a real Postgres."""

from __future__ import annotations

import asyncpg
import pytest

from common.contract import keys
from common.contract.migrate import (
    Migration,
    apply_migrations,
    contract_migrations,
    current_version,
    parse_migrations,
)
from common.errors import InternalError, MigrationError


async def test_migrations_apply_to_an_empty_database_and_reapply_as_a_no_op(
    empty_db_url: str,
) -> None:
    conn = await asyncpg.connect(empty_db_url)
    try:
        assert await current_version(conn) == 0
        applied = await apply_migrations(conn)
        assert applied == [m.version for m in contract_migrations()]
        assert await current_version(conn) == len(contract_migrations())
        tables = {
            r["tablename"]
            for r in await conn.fetch("SELECT tablename FROM pg_tables WHERE schemaname='public'")
        }
        assert tables == set(keys.TABLES)
        builtin = {r["code"] for r in await conn.fetch("SELECT code FROM strategy")}
        assert {"GOTO_AVOID", "GOTO_DIRECT", "CHARGE", "IDLE"} <= builtin

        assert await apply_migrations(conn) == []
        assert await conn.fetchval("SELECT count(*) FROM strategy") == len(builtin)
    finally:
        await conn.close()


async def test_an_edited_applied_migration_is_refused(empty_db_url: str) -> None:
    conn = await asyncpg.connect(empty_db_url)
    try:
        first = Migration(1, "first", "CREATE TABLE a (x int);")
        await apply_migrations(conn, (first,))
        edited = Migration(1, "first", "CREATE TABLE a (x bigint);")
        with pytest.raises(MigrationError, match="append-only"):
            await apply_migrations(conn, (edited,))
    finally:
        await conn.close()


async def test_a_new_migration_applies_on_top_of_older_ones(empty_db_url: str) -> None:
    conn = await asyncpg.connect(empty_db_url)
    try:
        first = Migration(1, "first", "CREATE TABLE a (x int);")
        second = Migration(2, "second", "ALTER TABLE a ADD COLUMN y int;")
        assert await apply_migrations(conn, (first,)) == [1]
        assert await apply_migrations(conn, (first, second)) == [2]
        assert await current_version(conn) == 2
    finally:
        await conn.close()


async def test_a_failing_migration_leaves_the_database_as_it_was(empty_db_url: str) -> None:
    conn = await asyncpg.connect(empty_db_url)
    try:
        bad = Migration(1, "bad", "CREATE TABLE a (x int); SELECT no_such_function();")
        with pytest.raises(MigrationError):
            await apply_migrations(conn, (bad,))
        assert await current_version(conn) == 0
        assert await conn.fetchval("SELECT to_regclass('a')") is None
    finally:
        await conn.close()


async def test_a_database_newer_than_the_code_is_refused(empty_db_url: str) -> None:
    conn = await asyncpg.connect(empty_db_url)
    try:
        first = Migration(1, "first", "CREATE TABLE a (x int);")
        second = Migration(2, "second", "CREATE TABLE b (x int);")
        await apply_migrations(conn, (first, second))
        with pytest.raises(MigrationError, match="newer than this code"):
            await apply_migrations(conn, (first,))
    finally:
        await conn.close()


def test_migration_numbers_must_run_without_gaps() -> None:
    text = "-- migration 1: a\nSELECT 1;\n-- migration 3: c\nSELECT 3;\n"
    with pytest.raises(InternalError, match="numbered"):
        parse_migrations(text)


def test_schema_sql_splits_into_numbered_migrations() -> None:
    migrations = contract_migrations()
    assert [m.version for m in migrations] == list(range(1, len(migrations) + 1))
    assert all(m.sql.strip() for m in migrations)


async def test_pnav_migrate_applies_the_contract_once(empty_db_url: str) -> None:
    import asyncio
    import os
    import sys

    async def migrate() -> tuple[int, str]:
        process = await asyncio.create_subprocess_exec(
            sys.executable,
            "-m",
            "pnav",
            "migrate",
            env={**os.environ, "PNAV_DATABASE_URL": empty_db_url},
            stdout=asyncio.subprocess.PIPE,
        )
        out, _ = await asyncio.wait_for(process.communicate(), 60)
        return process.returncode or 0, out.decode()

    newest = len(contract_migrations())
    assert await migrate() == (
        0,
        f"contract at version {newest}; applied now: {list(range(1, newest + 1))}\n",
    )
    assert await migrate() == (0, f"contract at version {newest}; applied now: nothing\n")

"""Apply the contract's numbered migrations (``schema.sql``) to a database, idempotently.

Each migration runs in its own transaction and is recorded in ``schema_version`` with a
checksum of its text. Concurrent callers (several services starting at once) serialise on a
Postgres advisory lock, so exactly one applies each migration. A migration already applied
whose text has since changed is refused: the contract is append-only.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass
from functools import cache
from importlib import resources

import asyncpg

from common.errors import InternalError, MigrationError

# An arbitrary constant: the advisory-lock key reserved for migrations.
_LOCK_KEY = 0x706E6176  # "pnav"
_HEADER = re.compile(r"^-- migration (\d+): (.+)$", re.MULTILINE)

_CREATE_VERSION_TABLE = """
CREATE TABLE IF NOT EXISTS schema_version (
    version    integer PRIMARY KEY,
    name       text NOT NULL,
    checksum   text NOT NULL,
    applied_at timestamptz NOT NULL DEFAULT now()
)"""


@dataclass(frozen=True)
class Migration:
    version: int
    name: str
    sql: str

    @property
    def checksum(self) -> str:
        return hashlib.sha256(self.sql.strip().encode()).hexdigest()


def parse_migrations(text: str) -> list[Migration]:
    """Split schema.sql text into migrations; numbering must run 1, 2, 3... with no gap."""
    headers = list(_HEADER.finditer(text))
    migrations = []
    for i, match in enumerate(headers):
        end = headers[i + 1].start() if i + 1 < len(headers) else len(text)
        migrations.append(Migration(int(match[1]), match[2].strip(), text[match.end() : end]))
    expected = list(range(1, len(migrations) + 1))
    if [m.version for m in migrations] != expected:
        raise InternalError(
            f"schema.sql migrations must be numbered {expected}, "
            f"found {[m.version for m in migrations]}"
        )
    return migrations


def schema_text() -> str:
    return resources.files("common.contract").joinpath("schema.sql").read_text()


@cache
def contract_migrations() -> tuple[Migration, ...]:
    return tuple(parse_migrations(schema_text()))


async def apply_migrations(
    conn: asyncpg.Connection, migrations: tuple[Migration, ...] | None = None
) -> list[int]:
    """Bring the database up to the newest contract version; return the versions applied."""
    migrations = contract_migrations() if migrations is None else migrations
    applied_now: list[int] = []
    try:
        await conn.execute("SELECT pg_advisory_lock($1)", _LOCK_KEY)
        try:
            await conn.execute(_CREATE_VERSION_TABLE)
            rows = await conn.fetch("SELECT version, checksum FROM schema_version")
            applied = {row["version"]: row["checksum"] for row in rows}
            for migration in migrations:
                recorded = applied.get(migration.version)
                if recorded is not None:
                    if recorded != migration.checksum:
                        raise MigrationError(
                            f"migration {migration.version} ({migration.name}) was applied to "
                            "this database with different text; the contract is append-only: "
                            "add a new migration instead of editing an applied one"
                        )
                    continue
                async with conn.transaction():
                    await conn.execute(migration.sql)
                    await conn.execute(
                        "INSERT INTO schema_version (version, name, checksum) VALUES ($1, $2, $3)",
                        migration.version,
                        migration.name,
                        migration.checksum,
                    )
                applied_now.append(migration.version)
            newest = max(applied, default=0)
            known = len(migrations)
            if newest > known:
                raise MigrationError(
                    f"the database is at contract version {newest}, newer than this code's "
                    f"{known}: upgrade proactive-nav"
                )
        finally:
            await conn.execute("SELECT pg_advisory_unlock($1)", _LOCK_KEY)
    except asyncpg.PostgresError as exc:
        raise MigrationError(f"applying the contract failed: {exc}") from exc
    return applied_now


async def current_version(conn: asyncpg.Connection) -> int:
    exists = await conn.fetchval("SELECT to_regclass('schema_version') IS NOT NULL")
    if not exists:
        return 0
    return int(await conn.fetchval("SELECT coalesce(max(version), 0) FROM schema_version"))

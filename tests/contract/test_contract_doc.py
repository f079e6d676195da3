"""CONTRACT.md documents every table and column of schema.sql, and keys.py names them all."""

from __future__ import annotations

import re
from pathlib import Path

import asyncpg

from common.contract import keys

CONTRACT = Path(keys.__file__).with_name("CONTRACT.md")


def documented_columns() -> dict[str, set[str]]:
    """Table name -> column names, from the `| column | ...` table under each '### name'."""
    tables: dict[str, set[str]] = {}
    section: set[str] | None = None
    in_columns = False
    for line in CONTRACT.read_text().splitlines():
        heading = re.match(r"^### (\w+)$", line)
        if heading:
            section, in_columns = tables.setdefault(heading[1], set()), False
        elif line.startswith("## "):
            section, in_columns = None, False
        elif section is not None and line.startswith("| column"):
            in_columns = True
        elif in_columns and line.startswith("| ") and not line.startswith("|---"):
            cell = line.split("|")[1].strip()
            section.update(name.strip() for name in cell.split(","))
        elif not line.startswith("|"):
            in_columns = False
    return tables


async def test_every_table_and_column_is_documented(conn: asyncpg.Connection) -> None:
    rows = await conn.fetch(
        "SELECT table_name, column_name FROM information_schema.columns "
        "WHERE table_schema = 'public'"
    )
    actual: dict[str, set[str]] = {}
    for row in rows:
        actual.setdefault(row["table_name"], set()).add(row["column_name"])
    documented = documented_columns()
    missing_tables = set(actual) - set(documented)
    assert not missing_tables, f"tables not in CONTRACT.md: {sorted(missing_tables)}"
    for table, columns in actual.items():
        assert columns == documented[table], (
            f"{table}: undocumented {sorted(columns - documented[table])}, "
            f"documented but absent {sorted(documented[table] - columns)}"
        )


async def test_keys_names_every_table(conn: asyncpg.Connection) -> None:
    tables = {
        r["tablename"]
        for r in await conn.fetch("SELECT tablename FROM pg_tables WHERE schemaname = 'public'")
    }
    assert tables == set(keys.TABLES)


def test_key_expressions_round_trip() -> None:
    assert keys.parse_notify_key(keys.notify_key(keys.GOAL, "r1")) == ("goal", "r1")
    assert keys.parse_notify_key(keys.notify_key(keys.STRATEGY)) == ("strategy", None)
    assert keys.parse_robot_key(keys.robot_key("r1", keys.SCAN)) == ("r1", "scan")
    assert keys.valid_id("robot_7-b") and not keys.valid_id("a/b") and not keys.valid_id("")

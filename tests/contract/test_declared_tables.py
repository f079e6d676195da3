"""Each table declared in common.contract.tables is the live table after every migration:
the same columns in the same order, each of the same Postgres type and nullability. The
writers' INSERTs, the row images and the readers' records come from the declarations
(common.contract.inserts, common.contract.records), so a column added by a migration and
not declared, or declared and not migrated, fails here rather than in a running service."""

from __future__ import annotations

from dataclasses import fields

import asyncpg
import pytest

from common.contract import tables
from common.contract.columns import Table
from common.contract.recommendations import RECOMMENDATION_COLUMNS, Recommendation

_LIVE = """
SELECT a.attname, format_type(a.atttypid, a.atttypmod), NOT a.attnotnull
FROM pg_attribute a
WHERE a.attrelid = $1::regclass AND a.attnum > 0 AND NOT a.attisdropped
ORDER BY a.attnum
"""


@pytest.mark.parametrize("table", list(tables.DECLARED.values()), ids=lambda t: t.name)
async def test_each_declaration_is_the_live_table(conn: asyncpg.Connection, table: Table) -> None:
    live = [tuple(row) for row in await conn.fetch(_LIVE, table.name)]
    declared = [(c.name, c.sql_type, c.nullable) for c in table.columns]
    assert declared == live


def test_every_imaged_table_is_declared() -> None:
    assert set(tables.IMAGED) <= set(tables.DECLARED)


def test_a_recommendation_is_its_declared_columns_in_order() -> None:
    written = [f.name for f in fields(Recommendation) if not f.kw_only]
    assert written == [c.name for c in tables.COMMAND_RECOMMENDATION.inserted]
    assert list(RECOMMENDATION_COLUMNS) == written

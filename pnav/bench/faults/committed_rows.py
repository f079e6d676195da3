"""Rows committed before a fault, looked for after it: "0 committed rows lost".

Every contract table is snapshotted by its primary key just before the fault, and the keys
are looked up again once the stack has recovered. The sensor tables (and planned_path) are
pruned by ``retention_policy`` as a matter of course, so for them only the newest
``SENSOR_SAMPLE`` rows are taken, and a row that retention would have pruned by the time of
the check (older than the ``keep_rows_per_robot``-th newest of its robot) is not counted.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import asyncpg

from common.contract import keys

SENSOR_SAMPLE = 100

_PKEY = """
SELECT a.attname FROM pg_index i
JOIN pg_attribute a ON a.attrelid = i.indrelid AND a.attnum = ANY(i.indkey)
WHERE i.indrelid = $1::regclass AND i.indisprimary ORDER BY a.attnum"""


@dataclass
class Snapshot:
    keys: dict[str, set[str]] = field(default_factory=dict)  # table -> primary keys as text
    pruned: dict[str, int] = field(default_factory=dict)  # retention table -> keep per robot

    @property
    def rows(self) -> int:
        return sum(len(v) for v in self.keys.values())


def _key_sql(columns: list[str]) -> str:
    return " || '|' || ".join(f"{c}::text" for c in columns)


async def snapshot(conn: asyncpg.Connection) -> Snapshot:
    snap = Snapshot()
    policy = {
        r["table_name"]: r["keep_rows_per_robot"]
        for r in await conn.fetch(
            f"SELECT table_name, keep_rows_per_robot FROM {keys.RETENTION_POLICY}"
        )
    }
    for table in keys.TABLES:
        columns = [r[0] for r in await conn.fetch(_PKEY, table)]
        if not columns:
            continue
        if table in policy:
            sql = f"SELECT id::text FROM {table} ORDER BY id DESC LIMIT {SENSOR_SAMPLE}"
            snap.pruned[table] = policy[table]
        else:
            sql = f"SELECT {_key_sql(columns)} FROM {table}"
        snap.keys[table] = {r[0] for r in await conn.fetch(sql)}
    return snap


async def lost(conn: asyncpg.Connection, before: Snapshot) -> dict[str, int]:
    """Per table, the rows of ``before`` that are gone (none: an empty dict)."""
    out: dict[str, int] = {}
    for table, wanted in before.keys.items():
        if not wanted:
            continue
        columns = [r[0] for r in await conn.fetch(_PKEY, table)]
        present = {
            r[0]
            for r in await conn.fetch(
                f"SELECT k FROM (SELECT {_key_sql(columns)} AS k FROM {table}) t "
                "WHERE k = ANY($1::text[])",
                list(wanted),
            )
        }
        missing = wanted - present
        keep = before.pruned.get(table)
        if missing and keep is not None:
            # older than the keep-th newest row of its robot: retention's, not the fault's
            kept = await conn.fetch(
                f"SELECT id::text FROM (SELECT id, row_number() OVER (PARTITION BY robot_id "
                f"ORDER BY id DESC) AS n FROM {table}) t WHERE n <= $1",
                keep,
            )
            floor = min((int(r[0]) for r in kept), default=0)
            missing = {m for m in missing if int(m) >= floor}
        if missing:
            out[table] = len(missing)
    return out

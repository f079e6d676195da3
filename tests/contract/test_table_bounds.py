"""common.contract.tables declares each imaged table's bounds once: they are the database's.

For every declared bound, a row just outside it is refused by the live database with one of
the constraints the declaration names, and a row just inside is accepted; a bound declared
as the writer's rule (no constraint) is one the database does accept, so the two are never
confused. The images readers judge (common.images) are held to exactly these.
"""

from __future__ import annotations

import math
from collections.abc import AsyncIterator, Mapping
from typing import Any

import asyncpg
import pytest

from common.contract import tables
from common.contract.columns import FLOAT, ID, INT, Column, Table

INF = math.inf

# A row every table accepts, in image form (no id: the sequence gives it).
VALID: dict[str, dict[str, Any]] = {
    "command_recommendation": {
        "robot_id": "r1",
        "kind": "robot",
        "source": "probe",
        "priority": 10,
        "linear_mps": 0.2,
        "angular_rps": 0.0,
        "system_command": None,
        "stamp": 10.0,
        "expires_stamp": 10.5,
        "inputs": "{}",
        "reason": "",
    },
    "command2robot": {
        "robot_id": "r1",
        "stamp": 10.0,
        "linear_mps": 0.2,
        "angular_rps": 0.0,
        "recommendation_id": 7,
        "source": "probe",
        "considered_ids": [7],
        "reason": "",
    },
    "odometry": {
        "robot_id": "r1",
        "stamp": 1.0,
        "seq": 0,
        "x": 0.0,
        "y": 0.0,
        "yaw": 0.0,
        "linear_mps": 0.0,
        "angular_rps": 0.0,
    },
    "laser_scan": {
        "robot_id": "r1",
        "stamp": 1.0,
        "seq": 0,
        "angle_min": 0.0,
        "angle_increment": 0.0175,
        "range_min": 0.12,
        "range_max": 3.5,
        "ranges": [INF, 0.5],
    },
    "battery": {
        "robot_id": "r1",
        "stamp": 1.0,
        "energy_wh": 5.0,
        "capacity_wh": 19.98,
        "percentage": 50.0,
        "charging": False,
        "power_w": 1.0,
    },
    "planned_path": {
        "robot_id": "r1",
        "stamp": 1.0,
        "goal_id": None,
        "target": "goal",
        "target_x": 1.0,
        "target_y": 1.0,
        "xs": [0.0, 1.0],
        "ys": [0.0, 1.0],
        "length_m": 1.4,
    },
}


# What a value just inside one bound needs of the other columns to keep the rules across
# them (the safety band, a system recommendation's command).
COMPANIONS: dict[tuple[str, Any], dict[str, Any]] = {
    ("priority", 1000): {"linear_mps": 0.0},
    ("kind", "system"): {"system_command": "CMD_BATTSAVE", "linear_mps": None, "angular_rps": None},
}


@pytest.fixture
async def client(db_url: str) -> AsyncIterator[asyncpg.Connection]:
    conn = await asyncpg.connect(db_url)  # a bare client, as a foreign writer has
    await conn.execute("INSERT INTO robot (robot_id) VALUES ('r1')")
    try:
        yield conn
    finally:
        await conn.close()


async def insert(conn: asyncpg.Connection, table: str, row: Mapping[str, Any]) -> None:
    names = list(row)
    values = ", ".join(f"${i}" for i in range(1, len(names) + 1))
    await conn.execute(f"INSERT INTO {table} ({', '.join(names)}) VALUES ({values})", *row.values())


async def outcome(conn: asyncpg.Connection, table: str, row: Mapping[str, Any]) -> str | None:
    """None if the database took ``row``, else the constraint (or error) that refused it;
    nothing is kept either way."""
    tx = conn.transaction()
    await tx.start()
    try:
        await insert(conn, table, row)
        return None
    except asyncpg.CheckViolationError as exc:
        return str(exc.constraint_name)
    except asyncpg.NotNullViolationError:
        return "NOT NULL"
    finally:
        await tx.rollback()


def as_image(row: Mapping[str, Any]) -> dict[str, Any]:
    """``row`` as its notification would carry it: with an id, jsonb as a map."""
    image = {**row, "id": 1}
    if "inputs" in image:
        image["inputs"] = {}
    return image


def _step(column: Column, v: float, up: bool) -> float:
    if column.type in (INT, ID):
        return v + 1 if up else v - 1
    return math.nextafter(v, INF if up else -INF)


def probes(column: Column) -> tuple[list[Any], list[Any]]:
    """Values just outside the column's bounds, and just inside them."""
    outside: list[Any] = []
    inside: list[Any] = []
    if column.type == FLOAT and (column.finite or column.abs_high is not None):
        outside += [math.nan, INF, -INF]
    if column.low is not None:
        low = column.low
        outside.append(low if column.low_open else _step(column, low, up=False))
        inside.append(_step(column, low, up=True) if column.low_open else low)
    if column.high is not None:
        outside.append(_step(column, column.high, up=True))
        inside.append(column.high)
    if column.abs_high is not None:
        for sign in (1, -1):
            outside.append(sign * _step(column, column.abs_high, up=True))
            inside.append(sign * column.abs_high)
    if column.choices:
        outside.append("bogus")
        inside += list(column.choices)
    return outside, inside


def judged(table: Table) -> list[Column]:
    return [c for c in table.columns if c.name in VALID[table.name]]


@pytest.mark.parametrize("table", list(tables.IMAGED.values()), ids=lambda t: t.name)
async def test_every_declared_bound_is_the_databases(
    client: asyncpg.Connection, table: Table
) -> None:
    base = VALID[table.name]
    assert await outcome(client, table.name, base) is None
    assert table.refusal(as_image(base), "r1") is None
    checked = 0
    for column in judged(table):
        outside, inside = probes(column)
        for value in outside:
            row = {**base, column.name: value}
            refused = await outcome(client, table.name, row)
            if column.checks:
                assert refused in column.checks, (table.name, column.name, value, refused)
            else:  # the writer's rule: the table takes it, the reader does not
                assert refused is None, (table.name, column.name, value, refused)
            assert column.refusal(value) is not None, (column.name, value)
            checked += 1
        for value in inside:
            row = {**base, column.name: value, **COMPANIONS.get((column.name, value), {})}
            assert await outcome(client, table.name, row) is None, (column.name, value)
            assert column.refusal(value) is None, (column.name, value)
        if not column.nullable and column.name != "robot_id":
            assert await outcome(client, table.name, {**base, column.name: None}) is not None
            assert column.refusal(None) == "NULL"
        elif column.nullable:
            # NULL is taken unless a rule across columns needs the value
            assert column.refusal(None) is None
    assert checked > 0


@pytest.mark.parametrize("table", list(tables.IMAGED.values()), ids=lambda t: t.name)
async def test_every_declared_rule_is_the_databases(
    client: asyncpg.Connection, table: Table
) -> None:
    base = VALID[table.name]
    image = as_image(base)
    for rule in table.rules:
        for change in rule.refuses:
            refused = await outcome(client, table.name, {**base, **change})
            if rule.checks:
                assert refused in rule.checks, (rule.says, change, refused)
            else:
                assert refused is None, (rule.says, change, refused)
            assert table.refusal({**image, **change}, "r1") is not None, (rule.says, change)
        for change in rule.accepts:
            assert await outcome(client, table.name, {**base, **change}) is None, change
            assert table.refusal({**image, **change}, "r1") is None, (rule.says, change)


async def test_ids_come_from_sequences_that_start_at_1(client: asyncpg.Connection) -> None:
    rows = await client.fetch(
        "SELECT sequencename, min_value, start_value, increment_by FROM pg_sequences "
        "WHERE sequencename = ANY($1::text[])",
        [f"{name}_id_seq" for name in tables.IMAGED],
    )
    assert len(rows) == len(tables.IMAGED)
    for row in rows:
        assert (row["min_value"], row["start_value"], row["increment_by"]) == (1, 1, 1)


async def test_an_image_on_another_robots_key_is_refused() -> None:
    image = {**VALID["odometry"], "id": 3}
    assert tables.ODOMETRY.refusal(image, "r1") is None
    assert tables.ODOMETRY.refusal(image, "r2") is not None
    assert tables.ODOMETRY.refusal({k: v for k, v in image.items() if k != "robot_id"}, "r1")


def test_the_documented_writers_are_the_roles_table() -> None:
    assert tables.COMMAND_RECOMMENDATION.writers() == {"planner", "controller"}
    assert tables.COMMAND2ROBOT.writers() == {"decision"}
    assert tables.ODOMETRY.writers() == {"bridge"}
    assert tables.PLANNED_PATH.writers() == {"planner"}

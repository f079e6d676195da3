"""Migration 11: a strategy row is bounded (params depth, size and numbers; code and
description lengths), the database refuses the rest whoever writes it, the Python mirror in
common.contract.limits agrees at every bound, and a row older than the bound does not stop
the readers the scenario services share (common.contract.records).

Plain SQL through a bare asyncpg connection, as a foreign client would speak it.
"""

from __future__ import annotations

import json
from collections.abc import AsyncIterator
from typing import Any

import asyncpg
import pytest

from common.contract import limits, records
from common.db import create_pool
from common.errors import ContractError

INSERT = "INSERT INTO strategy (code, params, description) VALUES ($1, $2::jsonb, $3)"


@pytest.fixture
async def client(db_url: str) -> AsyncIterator[asyncpg.Connection]:
    conn = await asyncpg.connect(db_url)
    try:
        yield conn
    finally:
        await conn.close()


def nested(depth: int) -> dict[str, Any]:
    """A params object ``depth`` deep (the object itself counting one)."""
    inner: Any = 1
    for _ in range(depth - 1):
        inner = [inner]
    return {"k": inner}


def nested_text(depth: int) -> str:
    """``nested(depth)`` as JSON text (json.dumps itself recurses, and gives up near 1 000)."""
    return '{"k": ' + "[" * (depth - 1) + "1" + "]" * (depth - 1) + "}"


def text_of(size: int) -> dict[str, Any]:
    """A params object whose JSON text (as Postgres writes it) is ``size`` bytes."""
    return {"k": "x" * (size - len('{"k": ""}'))}


async def refused_by(
    conn: asyncpg.Connection, code: str, params: Any, description: str = ""
) -> str:
    text = params if isinstance(params, str) else json.dumps(params)
    with pytest.raises(asyncpg.CheckViolationError) as caught:
        await conn.execute(INSERT, code, text, description)
    return str(caught.value.constraint_name)


def python_refuses(params: Any) -> bool:
    try:
        limits.check_params(params)
    except ContractError:
        return True
    return False


@pytest.mark.parametrize(
    ("value", "depth"),
    [
        ("1", 0),
        ('"x"', 0),
        ("{}", 1),
        ('{"a": 1}', 1),
        ('{"a": {"b": [1, [2]]}}', 4),
        ("[[], [[]]]", 3),
    ],
)
async def test_jsonb_depth_counts_the_objects_and_arrays_around_the_deepest_value(
    client: asyncpg.Connection, value: str, depth: int
) -> None:
    assert await client.fetchval("SELECT jsonb_depth($1::jsonb)", value) == depth
    assert limits.json_depth(json.loads(value)) == depth


async def test_jsonb_depth_with_stop_at_counts_no_further(client: asyncpg.Connection) -> None:
    deep = nested_text(3000)
    assert await client.fetchval("SELECT jsonb_depth($1::jsonb, 16)", deep) == 17
    assert await client.fetchval("SELECT jsonb_depth($1::jsonb)", deep) == 3000
    assert limits.json_depth(nested(3000), 16) == 17
    assert limits.json_depth(nested(3000)) == 3000


async def test_params_nested_500_deep_are_refused_and_the_bound_itself_accepted(
    client: asyncpg.Connection,
) -> None:
    bound = limits.MAX_PARAMS_DEPTH
    await client.execute(INSERT, "AT_BOUND", json.dumps(nested(bound)), "")
    for depth in (bound + 1, 500, 5000):
        refusal = await refused_by(client, f"DEEP_{depth}", nested_text(depth))
        assert refusal == "strategy_params_bounded"
        assert python_refuses(nested(depth))
    assert not python_refuses(nested(bound))
    # NOT VALID still guards every update, built-in strategies included
    with pytest.raises(asyncpg.CheckViolationError):
        await client.execute(
            "UPDATE strategy SET params = $1::jsonb WHERE code = 'GOTO_AVOID'",
            nested_text(500),
        )


async def test_params_size_bound_agrees_with_the_python_mirror(client: asyncpg.Connection) -> None:
    size = limits.MAX_PARAMS_BYTES
    at, above = text_of(size), text_of(size + 1)
    assert await client.fetchval("SELECT octet_length($1::jsonb::text)", json.dumps(at)) == size
    await client.execute(INSERT, "AT_SIZE", json.dumps(at), "")
    assert not python_refuses(at)
    assert await refused_by(client, "ABOVE_SIZE", above) == "strategy_params_bounded"
    assert python_refuses(above)


@pytest.mark.parametrize(
    ("params", "accepted"),
    [
        ({"k": {"n": limits.MAX_INT64}}, True),
        ({"k": [-limits.MAX_INT64]}, True),
        ({"k": {"n": limits.MAX_INT64 + 1}}, False),
        ({"k": [1, {"n": -(10**400)}]}, False),
        ({"k": {"n": 1e300}}, False),
    ],
)
async def test_every_number_at_any_depth_is_within_64_bits(
    client: asyncpg.Connection, params: dict[str, Any], accepted: bool
) -> None:
    if accepted:
        await client.execute(INSERT, "NUMBERS", json.dumps(params), "")
    else:
        assert await refused_by(client, "NUMBERS", params) == "strategy_params_bounded"
    assert python_refuses(params) is not accepted


async def test_code_and_description_lengths_are_bounded(client: asyncpg.Connection) -> None:
    code = "C" * limits.MAX_STRATEGY_CODE_CHARS
    text = "d" * limits.MAX_STRATEGY_DESCRIPTION_CHARS
    await client.execute(INSERT, code, "{}", text)
    assert await refused_by(client, code + "C", {}) == "strategy_text_bounded"
    assert await refused_by(client, "LONG", {}, text + "d") == "strategy_text_bounded"
    with pytest.raises(ContractError):
        limits.check_strategy_text(code + "C", "")
    with pytest.raises(ContractError):
        limits.check_strategy_text("LONG", text + "d")
    limits.check_strategy_text(code, text)


async def hostile_row(conn: asyncpg.Connection, code: str, params_sql: str) -> None:
    """A row the bound refuses, written as an owner could before migration 11: the check
    dropped, the row inserted, the check added back NOT VALID (the row stays)."""
    await conn.execute("ALTER TABLE strategy DROP CONSTRAINT strategy_params_bounded")
    await conn.execute(
        f"INSERT INTO strategy (code, params, description) VALUES ($1, {params_sql}, 'hostile')",
        code,
    )
    await conn.execute(
        "ALTER TABLE strategy ADD CONSTRAINT strategy_params_bounded "
        "CHECK (strategy_params_bounded(params)) NOT VALID"
    )


# 3000 deep: more than Python's json parser can read back (RecursionError), so a reader that
# decoded it would fail the whole query, every strategy with it
DEEP_SQL = "('{\"k\": ' || repeat('[', 3000) || repeat(']', 3000) || '}')::jsonb"


async def test_a_strategy_row_older_than_the_bound_is_read_with_no_params(
    client: asyncpg.Connection, db_url: str
) -> None:
    await hostile_row(client, "DEEP", DEEP_SQL)
    await client.execute(
        "INSERT INTO robot (robot_id) VALUES ('r1');"
        "INSERT INTO active_strategy (robot_id, strategy_code, source) "
        "VALUES ('r1', 'DEEP', 'user')"
    )
    pool = await create_pool(db_url)  # with the services' JSON codecs
    try:
        every = await records.strategies(pool)
        assert every["DEEP"].params == {}
        assert every["GOTO_AVOID"].params["target"] == "goal"
        active = await records.active_strategies(pool)
        assert active["r1"].strategy.code == "DEEP" and active["r1"].strategy.params == {}
        # what the bound saves them from: the row's params, decoded, fail the whole read
        with pytest.raises(RecursionError):
            await pool.fetch("SELECT params FROM strategy")
    finally:
        await pool.close()

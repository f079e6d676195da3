"""Migration 15: the robot table's footprint_polygon is refused at the door when it is not
a footprint, and common/footprint.py refuses exactly what the database does.

Plain SQL through a bare asyncpg connection, as a foreign client writes a robot row.
"""

from __future__ import annotations

import math
from collections.abc import AsyncIterator

import asyncpg
import pytest

from common.footprint import polygon_problem

NAN = math.nan
BOX = [[0.254, -0.215], [0.254, 0.215], [-0.254, 0.215], [-0.254, -0.215]]
UPDATE = "UPDATE robot SET footprint_polygon = $1 WHERE robot_id = 'r1'"


@pytest.fixture
async def client(db_url: str) -> AsyncIterator[asyncpg.Connection]:
    conn = await asyncpg.connect(db_url)
    await conn.execute("INSERT INTO robot (robot_id) VALUES ('r1')")
    try:
        yield conn
    finally:
        await conn.close()


async def refused(conn: asyncpg.Connection, polygon: object) -> str:
    with pytest.raises(asyncpg.CheckViolationError) as caught:
        await conn.execute(UPDATE, polygon)
    return str(caught.value.constraint_name)


async def test_a_box_is_stored_and_read_back_as_pairs(client: asyncpg.Connection) -> None:
    assert await client.fetchval("SELECT footprint_polygon FROM robot") is None  # the disc
    await client.execute(UPDATE, BOX)
    assert await client.fetchval("SELECT footprint_polygon FROM robot") == BOX
    await client.execute(UPDATE, None)  # back to the disc
    assert await client.fetchval("SELECT footprint_polygon FROM robot") is None


BAD = [
    # self-intersecting: bow ties, crossing beside the centre and on it
    ([[0.4, 0.2], [0.4, -0.2], [-0.2, 0.2], [-0.2, -0.2]], "robot_footprint_polygon_simple"),
    ([[0.2, 0.2], [-0.2, -0.2], [0.2, -0.2], [-0.2, 0.2]], "robot_footprint_polygon_simple"),
    # clockwise: the box reversed
    (BOX[::-1], "robot_footprint_polygon_simple"),
    # a vertex repeated
    ([*BOX[:2], BOX[1], *BOX[2:]], "robot_footprint_polygon_simple"),
    # a spike folding back along its edge
    (
        [[0.3, -0.2], [0.3, 0.2], [0.3, 0.0], [-0.3, 0.2], [-0.3, -0.2]],
        "robot_footprint_polygon_simple",
    ),
    # the centre outside: a box ahead of the robot
    (
        [[1.0, -0.2], [1.5, -0.2], [1.5, 0.2], [1.0, 0.2]],
        "robot_footprint_polygon_surrounds_centre",
    ),
    # the centre on an edge
    (
        [[0.0, -0.2], [0.5, -0.2], [0.5, 0.2], [0.0, 0.2]],
        "robot_footprint_polygon_surrounds_centre",
    ),
    # NaN, infinity, 10 m out
    ([[0.2, -0.2], [NAN, 0.2], [-0.2, 0.0]], "robot_footprint_polygon_bounded"),
    ([[0.2, -0.2], [math.inf, 0.2], [-0.2, 0.0]], "robot_footprint_polygon_bounded"),
    ([[0.2, -0.2], [10.0, 0.2], [-0.2, 0.0]], "robot_footprint_polygon_bounded"),
    # two vertices, 65 vertices, triples instead of pairs
    ([[0.2, -0.2], [0.2, 0.2]], "robot_footprint_polygon_bounded"),
    (
        [
            [0.3 * math.cos(2 * math.pi * k / 65), 0.3 * math.sin(2 * math.pi * k / 65)]
            for k in range(65)
        ],
        "robot_footprint_polygon_bounded",
    ),
    ([[0.2, -0.2, 0.0], [0.2, 0.2, 0.0], [-0.2, 0.0, 0.0]], "robot_footprint_polygon_bounded"),
]


@pytest.mark.parametrize(("polygon", "constraint"), BAD)
async def test_refused_naming_the_field(
    client: asyncpg.Connection, polygon: list[list[float]], constraint: str
) -> None:
    assert await refused(client, polygon) == constraint
    assert polygon_problem(polygon) is not None  # the tools refuse it first


async def test_a_flat_array_is_refused(client: asyncpg.Connection) -> None:
    flat = [0.2, -0.2, 0.2, 0.2, -0.2, 0.0]
    assert await refused(client, flat) == "robot_footprint_polygon_bounded"


async def test_the_python_check_accepts_what_the_database_accepts(
    client: asyncpg.Connection,
) -> None:
    # a concave L and a triangle round the centre: both valid, both stored
    for polygon in (
        [[0.3, -0.2], [0.3, 0.0], [0.05, 0.05], [0.05, 0.2], [-0.2, 0.2], [-0.2, -0.2]],
        [[0.3, 0.0], [-0.2, 0.2], [-0.2, -0.2]],
    ):
        assert polygon_problem(polygon) is None
        await client.execute(UPDATE, polygon)

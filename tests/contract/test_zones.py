"""Migration 14: the zone table refuses bad polygons and speeds, naming the field, whoever
writes them; common.contract.zones refuses the same first, in the same words; people may
write zones and the services may not.

The refusals speak plain SQL through asyncpg as a foreign client would.
"""

from __future__ import annotations

import math
import re
from collections.abc import AsyncIterator

import asyncpg
import pytest

from common.contract import zones
from common.contract.roles import bootstrap, role_url
from common.errors import ContractError

INSERT = (
    "INSERT INTO zone (name, kind, xs, ys, max_speed_mps) VALUES ($1, $2, $3::float8[], "
    "$4::float8[], $5)"
)
SQUARE = ([0.0, 2.0, 2.0, 0.0], [0.0, 0.0, 2.0, 2.0])

# (what, xs, ys, words the reason must hold)
BAD_POLYGONS = [
    ("self-intersecting", [0.0, 2.0, 2.0, 0.0], [0.0, 2.0, 0.0, 2.0], "edges 1 and 3 cross"),
    ("open (two vertices)", [0.0, 2.0], [0.0, 2.0], "at least 3"),
    ("closed explicitly", [0.0, 2.0, 2.0, 0.0], [0.0, 0.0, 2.0, 0.0], "repeats vertex 1"),
    ("degenerate (on one line)", [0.0, 1.0, 2.0], [0.0, 1.0, 2.0], "degenerate"),
    ("too small", [0.0, 0.05, 0.0], [0.0, 0.0, 0.05], "its area is"),
    ("repeated vertex", [0.0, 2.0, 2.0, 2.0], [0.0, 0.0, 0.0, 2.0], "same point"),
    ("NaN", [0.0, math.nan, 2.0], [0.0, 0.0, 2.0], "vertex 2 (xs[2], ys[2])"),
    ("infinite", [0.0, 2.0, 2.0], [0.0, 0.0, math.inf], "vertex 3"),
    ("too far", [0.0, 2.0e5, 2.0], [0.0, 0.0, 2.0], "within +-100000"),
    ("lengths differ", [0.0, 2.0, 2.0, 0.0], [0.0, 0.0, 2.0], "xs has 4 values but ys has 3"),
    ("too many vertices", [math.cos(i / 101) for i in range(101)], [0.0] * 101, "at most 100"),
    ("touching", [0.0, 4.0, 4.0, 2.0, 2.0, 0.0], [0.0, 0.0, 4.0, 0.0, 4.0, 4.0], "touch"),
    ("folding back", [0.0, 2.0, 1.0, 1.0], [0.0, 0.0, 0.0, 2.0], "fold back"),
]


def _gist(reason: str) -> str:
    """A reason up to its first number-bearing part."""
    return re.split(r"[:,] ", reason)[0]


@pytest.fixture
async def client(db_url: str) -> AsyncIterator[asyncpg.Connection]:
    conn = await asyncpg.connect(db_url)
    try:
        yield conn
    finally:
        await conn.close()


async def test_a_simple_polygon_of_either_kind_is_accepted(client: asyncpg.Connection) -> None:
    await client.execute(INSERT, "k", "keepout", *SQUARE, None)
    await client.execute(INSERT, "s", "speed_limit", *SQUARE, 0.3)
    # concave and clockwise are fine: only crossing edges are refused
    xs, ys = [0.0, 0.0, 1.0, 2.0, 2.0], [0.0, 2.0, 1.0, 2.0, 0.0]
    await client.execute(INSERT, "concave", "keepout", xs, ys, None)
    assert await client.fetchval("SELECT count(*) FROM zone") == 3


@pytest.mark.parametrize(
    ("what", "xs", "ys", "words"), BAD_POLYGONS, ids=[b[0] for b in BAD_POLYGONS]
)
async def test_a_bad_polygon_is_refused_naming_the_field(
    client: asyncpg.Connection, what: str, xs: list[float], ys: list[float], words: str
) -> None:
    with pytest.raises(asyncpg.CheckViolationError) as caught:
        await client.execute(INSERT, "z", "keepout", xs, ys, None)
    message = str(caught.value)
    assert caught.value.constraint_name == "zone_polygon"
    assert "zone polygon" in message and words in message, message
    # the Python mirror says the same, first (numbers aside: NaN prints as nan there)
    mirrored = zones.polygon_problem(xs, ys)
    assert mirrored is not None and _gist(mirrored) == _gist(message.removeprefix("zone ")), what
    with pytest.raises(ContractError, match="zone polygon"):
        zones.check_zone(zones.Zone("z", zones.KEEPOUT, tuple(xs), tuple(ys)))


async def test_a_valid_polygon_has_no_problem_in_either(client: asyncpg.Connection) -> None:
    for xs, ys in (SQUARE, ([0.0, 3.0, 0.0], [0.0, 0.0, 3.0])):
        assert await client.fetchval("SELECT zone_polygon_problem($1, $2)", xs, ys) is None
        assert zones.polygon_problem(xs, ys) is None


@pytest.mark.parametrize(
    ("kind", "speed", "constraint", "field"),
    [
        ("speed_limit", None, "zone_max_speed_mps_kind", "max_speed_mps"),
        ("keepout", 0.5, "zone_max_speed_mps_kind", "max_speed_mps"),
        ("speed_limit", 0.0, "zone_max_speed_mps_check", "max_speed_mps"),
        ("speed_limit", math.nan, "zone_max_speed_mps_check", "max_speed_mps"),
        ("speed_limit", 11.0, "zone_max_speed_mps_check", "max_speed_mps"),
        ("slow", 0.5, "zone_kind_check", "kind"),
    ],
)
async def test_a_bad_speed_or_kind_is_refused_naming_the_field(
    client: asyncpg.Connection, kind: str, speed: float | None, constraint: str, field: str
) -> None:
    with pytest.raises(asyncpg.CheckViolationError) as caught:
        await client.execute(INSERT, "z", kind, *SQUARE, speed)
    assert caught.value.constraint_name == constraint
    with pytest.raises(ContractError, match=f"zone {field}"):
        zones.check_zone(zones.Zone("z", kind, tuple(SQUARE[0]), tuple(SQUARE[1]), speed))


async def test_a_bad_name_is_refused(client: asyncpg.Connection) -> None:
    for name in ("", "a b", "x" * 65, "zone/1"):
        with pytest.raises(asyncpg.CheckViolationError) as caught:
            await client.execute(INSERT, name, "keepout", *SQUARE, None)
        assert caught.value.constraint_name == "zone_name_check"
        with pytest.raises(ContractError, match="zone name"):
            zones.check_zone(zones.Zone(name, zones.KEEPOUT, tuple(SQUARE[0]), tuple(SQUARE[1])))


def test_the_polygon_text_is_read_naming_the_option() -> None:
    assert zones.parse_polygon("0,0; 2,0; 2,2") == ((0.0, 2.0, 2.0), (0.0, 0.0, 2.0))
    with pytest.raises(ContractError, match="--polygon vertex 2 must be 'x,y'"):
        zones.parse_polygon("0,0; 2; 2,2")
    with pytest.raises(ContractError, match="--polygon vertex 1 must be two numbers"):
        zones.parse_polygon("a,b; 2,0; 2,2")


async def test_people_write_zones_and_services_only_read_them(empty_db_url: str) -> None:
    admin = await asyncpg.connect(empty_db_url)
    try:
        await bootstrap(admin)
    finally:
        await admin.close()
    user = await asyncpg.connect(role_url(empty_db_url, "pnav_user", None))
    try:
        await user.execute(INSERT, "k", "keepout", *SQUARE, None)
        await user.execute("UPDATE zone SET description = 'dock' WHERE name = 'k'")
        await user.execute("DELETE FROM zone WHERE name = 'k'")
        await user.execute(INSERT, "k", "keepout", *SQUARE, None)
    finally:
        await user.close()
    for role in ("pnav_planner", "pnav_bridge", "pnav_controller", "pnav_decision"):
        conn = await asyncpg.connect(role_url(empty_db_url, role, None))
        try:
            assert await conn.fetchval("SELECT count(*) FROM zone") == 1  # they read
            with pytest.raises(asyncpg.InsufficientPrivilegeError):
                await conn.execute(INSERT, "x", "keepout", *SQUARE, None)
            with pytest.raises(asyncpg.InsufficientPrivilegeError):
                await conn.execute("DELETE FROM zone")
        finally:
            await conn.close()


async def test_the_table_holds_at_most_256_zones(client: asyncpg.Connection) -> None:
    for i in range(zones.MAX_ZONES):
        await client.execute(INSERT, f"z{i}", "keepout", *SQUARE, None)
    with pytest.raises(asyncpg.CheckViolationError) as caught:
        await client.execute(INSERT, "one-more", "keepout", *SQUARE, None)
    assert caught.value.constraint_name == "zone_count"
    assert "at most 256 zones" in str(caught.value)
    await client.execute("DELETE FROM zone WHERE name = 'z0'")
    await client.execute(INSERT, "one-more", "keepout", *SQUARE, None)  # room again

"""The dashboard draws, adds and removes zones through its API: a zone is a zone row (as
`pnav zone add` writes it, notified), the page's world carries the zones, and a bad zone is
a 4xx naming the field with nothing written; another site's page cannot add one."""

from __future__ import annotations

from typing import Any

import httpx
import pytest

from common.runtime import Runtime
from pnav._testing import eventually
from tests.contract.dashboard.conftest import Running

pytestmark = pytest.mark.timeout(90)

SQUARE = {"xs": [0, 2, 2, 0], "ys": [0, 0, 2, 2]}


async def names(foreign: Runtime) -> list[str]:
    rows = await foreign.database.pool.fetch("SELECT name FROM zone ORDER BY name")
    return [r["name"] for r in rows]


async def test_a_zone_drawn_on_the_page_is_a_zone_row_in_the_world_and_removed_again(
    running: Running, foreign: Runtime, http: httpx.AsyncClient
) -> None:
    keepout = {"name": "dock", "kind": "keepout", **SQUARE}
    added = await http.post("/api/zones", json=keepout)
    assert added.status_code == 201, added.text
    assert added.json()["xs"] == [0.0, 2.0, 2.0, 0.0]
    slow = {"name": "aisle", "kind": "speed_limit", "max_speed_mps": 0.3, **SQUARE}
    assert (await http.post("/api/zones", json=slow)).status_code == 201
    assert await names(foreign) == ["aisle", "dock"]
    listed = (await http.get("/api/zones")).json()["zones"]
    assert [(z["name"], z["kind"], z["max_speed_mps"]) for z in listed] == [
        ("aisle", "speed_limit", 0.3),
        ("dock", "keepout", None),
    ]
    state = (await http.get("/api/state")).json()
    assert [z["name"] for z in state["world"]["zones"]] == ["aisle", "dock"]
    again = await http.post("/api/zones", json=keepout)
    assert again.status_code == 409 and "name" in again.json()["error"]

    removed = await http.delete("/api/zones/dock")
    assert removed.status_code == 200 and removed.json() == {"name": "dock", "removed": True}
    assert await names(foreign) == ["aisle"]
    gone = await http.delete("/api/zones/dock")
    assert gone.status_code == 404 and "no zone named 'dock'" in gone.json()["error"]

    # a zone written by another client (psql, notified as the CLI does) reaches the page
    await foreign.database.write(
        "zone",
        None,
        "INSERT INTO zone (name, kind, xs, ys) VALUES ('spill', 'keepout', $1, $2)",
        [5.0, 6.0, 6.0],
        [5.0, 5.0, 6.0],
    )
    store = running.dashboard.store
    await eventually(
        lambda: [z["name"] for z in store.world["zones"]] == ["aisle", "spill"],
        what="the page's world with the new zone",
    )


@pytest.mark.parametrize(
    ("body", "status", "words"),
    [
        (
            {"name": "x", "kind": "keepout", "xs": [0, 2, 2, 0], "ys": [0, 2, 0, 2]},
            422,
            "zone polygon edges 1 and 3 cross",
        ),
        (
            {"name": "x", "kind": "keepout", "xs": [0, 2], "ys": [0, 2]},
            422,
            "zone polygon has 2 vertices",
        ),
        (
            {"name": "x", "kind": "keepout", "xs": [0, 1, 2], "ys": [0, 1, 2]},
            422,
            "zone polygon is degenerate",
        ),
        (
            {"name": "x", "kind": "keepout", "xs": [0, 2, 2, 0], "ys": [0, 0, 2, 0]},
            422,
            "closed implicitly",
        ),
        (
            {"name": "x", "kind": "keepout", "xs": [0, 2, 2], "ys": [0, 0]},
            422,
            "xs has 3 values but ys has 2",
        ),
        (
            {"name": "x", "kind": "keepout", "xs": [0, "a", 2], "ys": [0, 0, 2]},
            422,
            "'xs' must hold numbers",
        ),
        (
            {"name": "x", "kind": "keepout", "xs": list(range(101)), "ys": [0] * 101},
            422,
            "'xs' must be a list of at most 100",
        ),
        ({"name": "x", "kind": "speed_limit", **SQUARE}, 422, "zone max_speed_mps"),
        (
            {"name": "x", "kind": "keepout", "max_speed_mps": 1, **SQUARE},
            422,
            "zone max_speed_mps must be empty",
        ),
        (
            {"name": "x", "kind": "speed_limit", "max_speed_mps": 0, **SQUARE},
            422,
            "zone max_speed_mps",
        ),
        ({"name": "x", "kind": "slow", **SQUARE}, 422, "zone kind"),
        ({"name": "a b", "kind": "keepout", **SQUARE}, 422, "zone name"),
        ({"name": "x", "kind": "keepout", "robot_id": "r 1", **SQUARE}, 422, "zone robot_id"),
        (
            {"name": "x", "kind": "keepout", "colour": "red", **SQUARE},
            422,
            "unknown field(s) colour",
        ),
    ],
)
async def test_a_bad_zone_is_refused_naming_the_field_and_nothing_is_written(
    running: Running,
    foreign: Runtime,
    http: httpx.AsyncClient,
    body: dict[str, Any],
    status: int,
    words: str,
) -> None:
    response = await http.post("/api/zones", json=body)
    assert response.status_code == status, response.text
    assert words in response.json()["error"], response.text
    assert await names(foreign) == []


async def test_nan_is_not_json_and_another_sites_page_cannot_add_a_zone(
    running: Running, foreign: Runtime, http: httpx.AsyncClient
) -> None:
    text = '{"name": "x", "kind": "keepout", "xs": [0, NaN, 2], "ys": [0, 0, 2]}'
    nan = await http.post("/api/zones", content=text, headers={"content-type": "application/json"})
    assert nan.status_code == 400
    cross = await http.post(
        "/api/zones",
        json={"name": "x", "kind": "keepout", **SQUARE},
        headers={"origin": "http://evil.example"},
    )
    assert cross.status_code == 403
    deleting = await http.delete("/api/zones/x", headers={"origin": "http://evil.example"})
    assert deleting.status_code == 403
    assert await names(foreign) == []

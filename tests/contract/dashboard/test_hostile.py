"""The dashboard trusts nothing it is sent or reads: a hostile body is a 4xx with its reason
and writes nothing, a page of another site (DNS rebinding, another scheme) is refused for
HTTP and websockets alike, and a row the page cannot draw is listed as unreadable while
everything else (listing, pushes, the timeline, a restart) goes on."""

from __future__ import annotations

import asyncio
import json
from typing import Any

import asyncpg
import httpx
import pytest
from websockets.asyncio.client import connect

from common.config import ZenohSettings
from common.contract import limits
from common.runtime import Runtime
from pnav._testing import eventually
from services.dashboard.settings import DashboardSettings
from tests.contract.dashboard.conftest import ROBOT, Fleet, Running, serving

pytestmark = pytest.mark.timeout(120)

COUNTS = "SELECT (SELECT count(*) FROM goal), (SELECT count(*) FROM strategy)"
GOAL = f"/api/robots/{ROBOT}/goal"


def deep_text(depth: int) -> str:
    return '{"k": ' + "[" * (depth - 1) + "1" + "]" * (depth - 1) + "}"


async def known_robot(running: Running, fleet: Fleet) -> None:
    await fleet.robot()
    await eventually(lambda: running.dashboard.store.fleet.known(ROBOT), what="the robot")


HOSTILE_BODIES: list[tuple[str, str, int, str]] = [
    # params nested 500 deep: the body itself is refused before parsing it
    ("/api/strategies", '{"code": "DEEP", "params": ' + deep_text(500) + "}", 400, "nests 501"),
    # a little too deep: the params' own reason
    (
        "/api/strategies",
        '{"code": "DEEP", "params": ' + deep_text(limits.MAX_PARAMS_DEPTH + 1) + "}",
        422,
        f"nest more than {limits.MAX_PARAMS_DEPTH} deep",
    ),
    ("/api/strategies", "[" * 990 + "]" * 990, 400, "nests 990 deep"),
    (GOAL, '{"x": ' + "1" * 400 + ', "y": 1}', 422, "400-digit integer is beyond 64 bits"),
    (GOAL, '{"x": 9223372036854775808, "y": 1}', 422, "beyond 64 bits"),
    (GOAL, '{"x": 1e400, "y": 1}', 422, "the number 1e400 is beyond a 64-bit float"),
    (
        "/api/strategies",
        '{"code": "BIG", "params": {"k": [' + "7" * 400 + "]}}",
        422,
        "400-digit integer",
    ),
    ("/api/strategies", '{"code": "BIG", "params": {"k": {"n": 1e300}}}', 422, "64 bits"),
    ("/api/strategies", json.dumps({"code": "C" * 65}), 422, "at most 64 characters"),
    ("/api/strategies", json.dumps({"code": "D", "description": "d" * 1001}), 422, "1000"),
    (
        "/api/strategies",
        json.dumps({"code": "D", "params": {"k": "x" * 70000}}),
        413,
        "over 65536 bytes",
    ),
    (
        "/api/strategies",
        json.dumps({"code": "D", "params": {"k": "x" * 17000}}),
        422,
        f"at most {limits.MAX_PARAMS_BYTES}",
    ),
]


@pytest.mark.parametrize(("path", "text", "status", "reason"), HOSTILE_BODIES)
async def test_a_hostile_body_is_a_4xx_with_its_reason_and_commits_nothing(
    running: Running,
    fleet: Fleet,
    foreign: Runtime,
    http: httpx.AsyncClient,
    path: str,
    text: str,
    status: int,
    reason: str,
) -> None:
    await known_robot(running, fleet)
    pool = foreign.database.pool
    before = tuple(await pool.fetchrow(COUNTS))
    response = await http.post(
        path, content=text.encode(), headers={"content-type": "application/json"}
    )
    assert response.status_code == status, response.text
    assert reason in response.json()["error"], response.json()
    assert "\n" not in response.json()["error"]
    assert tuple(await pool.fetchrow(COUNTS)) == before
    assert (await http.get("/api/strategies")).status_code == 200


async def test_an_id_beyond_64_bits_is_a_404(running: Running, http: httpx.AsyncClient) -> None:
    for path in ("/api/decisions/9223372036854775808", "/api/system-commands/" + "9" * 400):
        response = await http.get(path)
        assert response.status_code == 404, response.text
        assert "ids are 64-bit" in response.json()["error"]


async def test_a_strategy_with_an_empty_description_is_stored_with_an_empty_one(
    running: Running, foreign: Runtime, http: httpx.AsyncClient
) -> None:
    for code, description in (("QUIET", ""), ("QUIETER", None)):
        new = {"code": code, "planner_scenario": None, "description": description}
        response = await http.post("/api/strategies", json=new)
        assert response.status_code == 201, response.text
    rows = await foreign.database.pool.fetch(
        "SELECT code, description FROM strategy WHERE code LIKE 'QUIET%' ORDER BY code"
    )
    assert [(r["code"], r["description"]) for r in rows] == [("QUIET", ""), ("QUIETER", "")]


async def handshake(port: int, host: str, origin: str | None) -> int:
    """The HTTP status a websocket handshake to /ws gets with these Host and Origin headers
    (a raw request: a browser reaching the dashboard by another name sends exactly these)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    lines = [
        "GET /ws HTTP/1.1",
        f"Host: {host}",
        "Upgrade: websocket",
        "Connection: Upgrade",
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==",
        "Sec-WebSocket-Version: 13",
    ]
    if origin is not None:
        lines.append(f"Origin: {origin}")
    writer.write(("\r\n".join(lines) + "\r\n\r\n").encode())
    await writer.drain()
    status = await asyncio.wait_for(reader.readline(), 20)
    writer.close()
    return int(status.split()[1])


async def test_dns_rebinding_and_foreign_schemes_are_refused_for_writes_and_websockets(
    running: Running, fleet: Fleet, foreign: Runtime, http: httpx.AsyncClient
) -> None:
    await known_robot(running, fleet)
    port = running.dashboard.port
    rebound = f"evil.example:{port}"
    refused: list[dict[str, str]] = [
        # DNS rebinding: the other site's name, pointed at 127.0.0.1, with its own page
        {"host": rebound, "origin": f"http://{rebound}"},
        {"host": rebound},  # a client that sends no Origin still names the host
        # the dashboard's own host, but a page of another scheme, port or name
        {"host": f"127.0.0.1:{port}", "origin": f"https://127.0.0.1:{port}"},
        {"host": f"127.0.0.1:{port}", "origin": f"http://127.0.0.1:{port + 1}"},
        {"host": f"127.0.0.1:{port}", "origin": f"http://localhost:{port}"},
        {"host": f"127.0.0.1:{port}", "origin": "null"},
    ]
    for headers in refused:
        goal = await http.post(GOAL, json={"x": 1, "y": 1}, headers=headers)
        assert goal.status_code == 403, (headers, goal.text)
        assert "refused" in goal.json()["error"]
        assert await handshake(port, headers["host"], headers.get("origin")) == 403, headers
    assert (await http.get("/api/state", headers={"host": rebound})).status_code == 403
    assert await foreign.database.pool.fetchval("SELECT count(*) FROM goal") == 0
    # the dashboard's own page, by each of its own names
    for name in (f"127.0.0.1:{port}", f"localhost:{port}", f"[::1]:{port}"):
        own = {"host": name, "origin": f"http://{name}"}
        goal = await http.post(GOAL, json={"x": 1, "y": 1}, headers=own)
        assert goal.status_code == 201, (name, goal.text)
        assert await handshake(port, name, f"http://{name}") == 101, name


async def test_a_configured_name_is_the_dashboards_own(
    db_url: str, zenoh_settings: ZenohSettings
) -> None:
    env = {"PNAV_DASHBOARD_PORT": "0", "PNAV_DASHBOARD_ALLOWED_HOSTS": "robots.lan, Fleet.Example"}
    settings = DashboardSettings.from_env(env)
    async with serving(db_url, zenoh_settings, settings) as served:
        port = served.dashboard.port
        for name in ("robots.lan", "fleet.example"):
            assert await handshake(port, f"{name}:{port}", f"http://{name}:{port}") == 101
        assert await handshake(port, f"evil.example:{port}", None) == 403


async def hostile_rows(db_url: str) -> None:
    """What the hostile tester left, as an owner could before migration 11 (the check
    dropped, the rows written, the check added back NOT VALID): params nested 3000 deep
    (more than Python's JSON parser reads), params of 100 KB, a 5 000-digit number; and a
    goal and a user_command with a 100 KB argument for the timeline."""
    conn = await asyncpg.connect(db_url)
    try:
        await conn.execute("ALTER TABLE strategy DROP CONSTRAINT strategy_params_bounded")
        deep = "('{\"k\": ' || repeat('[', 3000) || repeat(']', 3000) || '}')::jsonb"
        large = "jsonb_build_object('k', repeat('x', 100000))"
        huge = "('{\"k\": {\"n\": ' || repeat('9', 5000) || '}}')::jsonb"
        for code, params in (("DEEP", deep), ("LARGE", large), ("HUGE", huge)):
            await conn.execute(f"INSERT INTO strategy (code, params) VALUES ('{code}', {params})")
        await conn.execute(
            "ALTER TABLE strategy ADD CONSTRAINT strategy_params_bounded "
            "CHECK (strategy_params_bounded(params)) NOT VALID"
        )
        await conn.execute(f"INSERT INTO robot (robot_id) VALUES ('{ROBOT}')")
        await conn.execute(f"INSERT INTO goal (robot_id, x, y) VALUES ('{ROBOT}', 1, 2)")
        await conn.execute(
            "INSERT INTO user_command (robot_id, command, argument) "
            f"VALUES ('{ROBOT}', 'SET_STRATEGY', repeat('A', 100000))"
        )
    finally:
        await conn.close()


def by_code(strategies: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    return {s["code"]: s for s in strategies}


async def test_rows_the_page_cannot_draw_are_unreadable_and_the_rest_works_across_restarts(
    db_url: str, zenoh_settings: ZenohSettings
) -> None:
    await hostile_rows(db_url)
    for _start in range(2):  # a restart reads the same rows again
        async with (
            serving(db_url, zenoh_settings) as served,
            httpx.AsyncClient(base_url=served.url, timeout=20) as http,
        ):
            listed = by_code((await http.get("/api/strategies")).json()["strategies"])
            for code in ("DEEP", "LARGE", "HUGE"):
                assert listed[code]["params"] is None
                assert "beyond the contract's bounds" in listed[code]["unreadable"]
            assert listed["GOTO_AVOID"]["params"]["target"] == "goal"
            assert listed["GOTO_AVOID"]["unreadable"] is None
            async with connect(served.ws_url) as ws:
                snapshot = json.loads(await asyncio.wait_for(ws.recv(), 20))
                assert snapshot["type"] == "snapshot"
                assert "DEEP" in by_code(snapshot["strategies"])
                texts = [e["text"] for e in snapshot["timeline"]]
                assert any(t.startswith("goal ") for t in texts), texts
                assert any("SET_STRATEGY AAAA" in t and len(t) < 300 for t in texts), texts
                # pushes go on: a new strategy reaches the page
                new = {"code": f"AFTER_{_start}", "planner_scenario": None}
                assert (await http.post("/api/strategies", json=new)).status_code == 201
                while True:
                    message = json.loads(await asyncio.wait_for(ws.recv(), 20))
                    if message["type"] == "strategies":
                        assert f"AFTER_{_start}" in by_code(message["strategies"])
                        break
            goal = await http.post(GOAL, json={"x": 3, "y": 4})
            assert goal.status_code == 201, goal.text

"""The dashboard writes people's rows (goal, user_command, strategy) as the CLI does, and
refuses a bad request with a 4xx, its reason, and nothing written."""

from __future__ import annotations

import asyncio
import math
from typing import Any

import httpx
import pytest

from common.contract import keys
from common.runtime import Runtime
from pnav._testing import eventually
from services.dashboard.orders import Orders
from services.dashboard.requests import GoalRequest, Refused
from tests.contract.dashboard.conftest import ROBOT, Fleet, Running

pytestmark = pytest.mark.timeout(90)

COUNTS = "SELECT (SELECT count(*) FROM goal), (SELECT count(*) FROM user_command), " + (
    "(SELECT count(*) FROM strategy)"
)


async def known_robot(running: Running, fleet: Fleet) -> None:
    await fleet.robot()
    await eventually(lambda: running.dashboard.store.fleet.known(ROBOT), what="the robot")


async def test_a_goal_is_a_goal_row_and_the_next_one_supersedes_it(
    running: Running, fleet: Fleet, foreign: Runtime, http: httpx.AsyncClient
) -> None:
    await known_robot(running, fleet)
    first = await http.post(f"/api/robots/{ROBOT}/goal", json={"x": 1, "y": 2})
    assert first.status_code == 201 and first.json()["x"] == 1.0
    second = await http.post(
        f"/api/robots/{ROBOT}/goal", json={"x": 3.5, "y": -1.25, "tolerance_m": 0.3}
    )
    assert second.status_code == 201
    rows = await foreign.database.pool.fetch(
        "SELECT id, x, y, tolerance_m, status, reason FROM goal ORDER BY id"
    )
    assert [(r["x"], r["y"], r["tolerance_m"], r["status"]) for r in rows] == [
        (1.0, 2.0, 0.15, "superseded"),
        (3.5, -1.25, 0.3, "active"),
    ]
    assert rows[1]["id"] == second.json()["goal_id"]


async def test_a_goal_pose_with_a_route_is_written_and_its_progress_shown(
    running: Running, fleet: Fleet, foreign: Runtime, http: httpx.AsyncClient
) -> None:
    await known_robot(running, fleet)
    body = {
        "x": 3.0,
        "y": 1.0,
        "yaw": 1.5,
        "waypoints": [{"x": 1.0, "y": 0.0}, {"x": 2.0, "y": 0.0, "yaw": -1.0, "stop": True}],
    }
    response = await http.post(ROBOT_GOAL, json=body)
    assert response.status_code == 201, response.text
    assert response.json()["yaw"] == 1.5 and response.json()["waypoints"] == 2
    goal = response.json()["goal_id"]
    pool = foreign.database.pool
    row = await pool.fetchrow("SELECT yaw, yaw_tolerance_rad FROM goal WHERE id = $1", goal)
    assert (row["yaw"], row["yaw_tolerance_rad"]) == (1.5, 0.1)
    # the planner's progress (played here), notified as the planner does
    await foreign.database.write(
        keys.GOAL_WAYPOINT,
        ROBOT,
        "UPDATE goal_waypoint SET status = 'reached', reached_stamp = 7.5 "
        "WHERE goal_id = $1 AND seq = 1 RETURNING seq",
        goal,
    )

    def shown() -> list[tuple[int, str]] | None:
        robot = running.dashboard.store.snapshot()["robots"].get(ROBOT) or {}
        route = [(w["seq"], w["status"]) for w in robot.get("route", [])]
        return route if route == [(1, "reached"), (2, "pending")] else None

    await eventually(shown, what="the route's progress on the page")
    robot = running.dashboard.store.snapshot()["robots"][ROBOT]
    assert robot["goal"]["yaw"] == 1.5 and robot["route"][1]["stop"] is True
    assert robot["route"][1]["yaw"] == -1.0 and robot["route"][0]["reached_stamp"] == 7.5


async def play_strategy_service(foreign: Runtime, verdict: str) -> None:
    """Treat the first pending user_command as the strategy service would."""
    pool = foreign.database.pool
    while True:
        row = await pool.fetchrow("SELECT id FROM user_command WHERE status = 'pending'")
        if row is not None:
            await foreign.database.write(
                keys.USER_COMMAND,
                ROBOT,
                "UPDATE user_command SET status = $2, reason = 'as asked', treated_at = now() "
                "WHERE id = $1 RETURNING id",
                row["id"],
                verdict,
            )
            return
        await asyncio.sleep(0.02)


async def test_a_strategy_switch_is_a_user_command_answered_with_its_verdict(
    running: Running, fleet: Fleet, foreign: Runtime, http: httpx.AsyncClient
) -> None:
    await known_robot(running, fleet)
    service = asyncio.create_task(play_strategy_service(foreign, "accepted"))
    response = await http.post(f"/api/robots/{ROBOT}/strategy", json={"code": "goto_direct"})
    await service
    assert response.status_code == 200, response.text
    answer = response.json()
    assert answer["code"] == "GOTO_DIRECT"
    assert (answer["status"], answer["reason"]) == ("accepted", "as asked")
    row = await foreign.database.pool.fetchrow("SELECT * FROM user_command")
    assert (row["command"], row["argument"], row["id"]) == (
        "SET_STRATEGY",
        "GOTO_DIRECT",
        answer["command_id"],
    )


async def test_a_new_strategy_is_a_strategy_row_offered_to_every_page(
    running: Running, foreign: Runtime, http: httpx.AsyncClient
) -> None:
    scenarios = (await http.get("/api/strategies")).json()["scenarios"]
    assert "turn_then_move" in scenarios["planner"]
    assert {"avoid_left", "safety_stop"} <= set(scenarios["controller"])
    new = {
        "code": "careful",
        "planner_scenario": "turn_then_move",
        "controller_scenarios": ["safety_stop"],
        "params": {"target": "goal", "safety_margin_m": 0.2},
        "description": "slow and safe",
    }
    response = await http.post("/api/strategies", json=new)
    assert response.status_code == 201, response.text
    row = await foreign.database.pool.fetchrow("SELECT * FROM strategy WHERE code = 'CAREFUL'")
    assert row["planner_scenario"] == "turn_then_move"
    assert row["controller_scenarios"] == ["safety_stop"]
    assert row["description"] == "slow and safe"
    listed = (await http.get("/api/strategies")).json()["strategies"]
    assert any(s["code"] == "CAREFUL" for s in listed)
    again = await http.post("/api/strategies", json=new)
    assert again.status_code == 409 and "exists already" in again.json()["error"]


ROBOT_GOAL = f"/api/robots/{ROBOT}/goal"
BAD_REQUESTS: list[tuple[str, str, str | dict[str, Any] | None, int, str]] = [
    ("POST", ROBOT_GOAL, '{"x": NaN, "y": 1}', 400, "not valid JSON"),
    ("POST", ROBOT_GOAL, '{"x": Infinity, "y": 1}', 400, "not valid JSON"),
    ("POST", ROBOT_GOAL, '{"x": 1, "y": ', 400, "not valid JSON"),
    ("POST", ROBOT_GOAL, "[1, 2]", 400, "must be a JSON object"),
    ("POST", ROBOT_GOAL, {"x": 1e9, "y": 1}, 422, "goal x must be a finite number"),
    ("POST", ROBOT_GOAL, {"x": 1, "y": 1, "tolerance_m": 0}, 422, "goal tolerance"),
    ("POST", ROBOT_GOAL, {"x": 1}, 422, "'y' is missing"),
    ("POST", ROBOT_GOAL, {"x": "1", "y": 1}, 422, "'x' must be a number"),
    ("POST", ROBOT_GOAL, {"x": True, "y": 1}, 422, "'x' must be a number"),
    ("POST", ROBOT_GOAL, {"x": 1, "y": 1, "z": 0}, 422, "unknown field(s) z"),
    ("POST", ROBOT_GOAL, '{"x": 1, "y": 1, "yaw": NaN}', 400, "not valid JSON"),
    ("POST", ROBOT_GOAL, {"x": 1, "y": 1, "yaw": 3.5}, 422, "goal yaw must be a finite angle"),
    ("POST", ROBOT_GOAL, {"x": 1, "y": 1, "yaw": "north"}, 422, "'yaw' must be a number"),
    (
        "POST",
        ROBOT_GOAL,
        {"x": 1, "y": 1, "yaw_tolerance_rad": 0.1},
        422,
        "goal yaw_tolerance_rad needs a yaw",
    ),
    (
        "POST",
        ROBOT_GOAL,
        {"x": 1, "y": 1, "yaw": 1, "yaw_tolerance_rad": 4},
        422,
        "goal yaw_tolerance_rad must be",
    ),
    ("POST", ROBOT_GOAL, {"x": 1, "y": 1, "waypoints": 3}, 422, "'waypoints' must be a list"),
    (
        "POST",
        ROBOT_GOAL,
        {"x": 1, "y": 1, "waypoints": [{"x": 0, "y": 0}, {"x": 1, "y": 0, "yaw": -4}]},
        422,
        "waypoint 2 yaw must be a finite angle",
    ),
    ("POST", ROBOT_GOAL, {"x": 1, "y": 1, "waypoints": [{"x": 0}]}, 422, "waypoint 1 'y' is"),
    (
        "POST",
        ROBOT_GOAL,
        {"x": 1, "y": 1, "waypoints": [{"x": 0, "y": 0, "stop": "yes"}]},
        422,
        "waypoint 1 'stop' must be true or false",
    ),
    (
        "POST",
        ROBOT_GOAL,
        {"x": 1, "y": 1, "waypoints": [[0, 0]] * 1001},
        422,
        "waypoints: at most 1000 per goal, got 1001",
    ),
    # 10 000 poses do not fit the body's 64 KiB: refused before any parse
    (
        "POST",
        ROBOT_GOAL,
        {"x": 1, "y": 1, "waypoints": [{"x": 1.5, "y": 2.5}] * 10_000},
        413,
        "the body is over",
    ),
    ("POST", "/api/robots/nobody/goal", {"x": 1, "y": 1}, 404, "no robot 'nobody'"),
    ("DELETE", "/api/robots/nobody/goal", None, 404, "no robot 'nobody'"),
    ("POST", "/api/robots/r1/strategy", {"code": "NO_SUCH"}, 422, "unknown strategy 'NO_SUCH'"),
    ("POST", "/api/robots/r1/strategy", {"code": "GO TO"}, 422, "must be a strategy code"),
    ("POST", "/api/robots/nobody/strategy", {"code": "IDLE"}, 404, "no robot 'nobody'"),
    (
        "POST",
        "/api/strategies",
        {"code": "X", "planner_scenario": "turn_then_mvoe"},
        422,
        "unknown planner scenario 'turn_then_mvoe'",
    ),
    (
        "POST",
        "/api/strategies",
        {"code": "X", "planner_scenario": None, "controller_scenarios": ["avoid_up"]},
        422,
        "unknown controller scenario(s) avoid_up",
    ),
    ("POST", "/api/strategies", {"code": "X", "params": {"k": 1e7}}, 422, "params.k"),
    ("POST", "/api/strategies", {"code": "X", "params": [1]}, 422, "'params' must be"),
    ("GET", "/api/decisions/999", None, 404, "no command2robot row 999"),
    ("PUT", ROBOT_GOAL, {"x": 1, "y": 1}, 405, "Method Not Allowed"),
]


@pytest.mark.parametrize(
    ("headers", "status", "reason"),
    [
        # what a form on another site can send without asking the dashboard first
        ({"content-type": "text/plain"}, 415, "send the body as application/json, not text/plain"),
        (
            {"content-type": "application/json", "origin": "http://evil.example"},
            403,
            "cross-origin request from http://evil.example refused",
        ),
    ],
)
async def test_a_request_from_another_sites_page_is_refused(
    running: Running,
    fleet: Fleet,
    foreign: Runtime,
    http: httpx.AsyncClient,
    headers: dict[str, str],
    status: int,
    reason: str,
) -> None:
    await known_robot(running, fleet)
    response = await http.post(ROBOT_GOAL, content=b'{"x": 1, "y": 1}', headers=headers)
    assert response.status_code == status and reason in response.json()["error"]
    cancel = await http.delete(ROBOT_GOAL, headers={"origin": "http://evil.example"})
    assert cancel.status_code == 403
    assert await foreign.database.pool.fetchval("SELECT count(*) FROM goal") == 0
    # the page's own origin is the dashboard's
    own = {"content-type": "application/json", "origin": running.url}
    response = await http.post(ROBOT_GOAL, content=b'{"x": 1, "y": 1}', headers=own)
    assert response.status_code == 201, response.text


@pytest.mark.parametrize(("method", "path", "payload", "status", "reason"), BAD_REQUESTS)
async def test_a_bad_request_gets_a_4xx_with_its_reason_and_writes_nothing(
    running: Running,
    fleet: Fleet,
    foreign: Runtime,
    http: httpx.AsyncClient,
    method: str,
    path: str,
    payload: str | dict[str, Any] | None,
    status: int,
    reason: str,
) -> None:
    await known_robot(running, fleet)
    pool = foreign.database.pool
    before = tuple(await pool.fetchrow(COUNTS))
    if isinstance(payload, str):
        json_type = {"content-type": "application/json"}
        response = await http.request(method, path, content=payload.encode(), headers=json_type)
    else:
        response = await http.request(method, path, json=payload)
    assert response.status_code == status, response.text
    assert reason in response.json()["error"], response.json()
    assert "\n" not in response.json()["error"]
    assert tuple(await pool.fetchrow(COUNTS)) == before


async def test_a_row_the_database_refuses_is_a_422_naming_the_constraint(
    running: Running, fleet: Fleet, foreign: Runtime
) -> None:
    """Past the page's own checks (a client calling the store with NaN), the CHECK
    constraint still refuses the row, and the refusal is a 422, not a 500."""
    await known_robot(running, fleet)
    with pytest.raises(Refused) as refused:
        await Orders(running.dashboard.store).set_goal(ROBOT, GoalRequest(math.nan, 1.0))
    assert refused.value.status == 422
    assert "goal_xy_bounded" in refused.value.reason
    assert await foreign.database.pool.fetchval("SELECT count(*) FROM goal") == 0

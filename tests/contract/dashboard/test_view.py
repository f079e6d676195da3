"""What the dashboard pushes over its websocket: a snapshot, then what changed, built from
the contract's rows and notifications alone."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from typing import Any

import httpx
import pytest
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import InvalidStatus

from common.contract import keys
from common.runtime import Runtime
from pnav._testing import eventually
from tests.contract.dashboard.conftest import ROBOT, Fleet, Running

pytestmark = pytest.mark.timeout(90)


async def next_message(
    ws: ClientConnection, wanted: Callable[[dict[str, Any]], bool], within: float = 15.0
) -> dict[str, Any]:
    """The first message ``wanted`` holds for (others are skipped)."""
    import asyncio

    async def scan() -> dict[str, Any]:
        while True:
            message: dict[str, Any] = json.loads(await ws.recv())
            if wanted(message):
                return message

    return await asyncio.wait_for(scan(), within)


def robot_update(robot: str, check: Callable[[dict[str, Any]], bool]) -> Callable[..., bool]:
    def wanted(message: dict[str, Any]) -> bool:
        state = message.get("robots", {}).get(robot)
        return message["type"] in ("robots", "snapshot") and state is not None and check(state)

    return wanted


async def test_the_page_and_its_script_are_served(http: httpx.AsyncClient) -> None:
    page = await http.get("/")
    assert page.status_code == 200 and "/static/dashboard.js" in page.text
    script = await http.get("/static/dashboard.js")
    assert script.status_code == 200 and "new WebSocket" in script.text
    assert (await http.get("/extra")).text == "mounted"  # extra routes share the port
    missing = await http.get("/no/such/page")
    assert missing.status_code == 404 and "error" in missing.json()


async def test_the_snapshot_shows_map_chargers_robot_pose_lidar_goal_path_and_strategy(
    running: Running, fleet: Fleet, foreign: Runtime
) -> None:
    await fleet.robot()
    await fleet.world()
    # the robot at (1, 1) facing +y; beam 0 (ahead) hits at 1 m, beam 1 (+x side... left
    # of +y is -x) at 2 m, the other two see nothing
    await fleet.odometry(1.0, 1.0, math.pi / 2)
    await fleet.scan([1.0, 2.0, math.inf, math.inf])
    pool = foreign.database.pool
    await pool.execute(
        "INSERT INTO goal (robot_id, x, y, tolerance_m) VALUES ($1, 3, 1.5, 0.2)", ROBOT
    )
    await pool.execute(
        "INSERT INTO planned_path (robot_id, stamp, target, target_x, target_y, xs, ys, "
        "length_m) VALUES ($1, 1, 'goal', 3, 1.5, '{1, 2, 3}', '{1, 1.5, 1.5}', 2.1)",
        ROBOT,
    )
    await pool.execute(
        "INSERT INTO active_strategy (robot_id, strategy_code, source, stamp) "
        "VALUES ($1, 'GOTO_AVOID', 'default', 1)",
        ROBOT,
    )
    # rows written without notifications are read on the dashboard's refresh: start anew
    await running.dashboard.store.refresh()
    async with connect(running.ws_url) as ws:
        snap = json.loads(await ws.recv())
    assert snap["type"] == "snapshot"
    grid = snap["world"]["map"]
    assert (grid["map_id"], grid["width"], grid["height"], grid["resolution"]) == (
        "room",
        4,
        2,
        0.5,
    )
    assert snap["world"]["chargers"] == [{"id": "dock", "x": 0.5, "y": 0.5, "radius_m": 0.3}]
    robot = snap["robots"][ROBOT]
    assert robot["limits"]["footprint_m"] == 0.105
    assert (robot["pose"]["x"], robot["pose"]["y"]) == (1.0, 1.0)
    # beam 0 straight ahead (+y): (1, 2); beam 1 a quarter turn left (-x): (-1, 1)
    assert robot["scan"]["points"] == [1.0, 2.0, -1.0, 1.0]
    assert robot["goal"]["status"] == "active" and robot["goal"]["x"] == 3.0
    assert robot["path"]["xs"] == [1.0, 2.0, 3.0] and robot["path"]["target"] == "goal"
    assert robot["strategy"]["code"] == "GOTO_AVOID"
    assert {s["code"] for s in snap["strategies"]} >= {"GOTO_AVOID", "GOTO_DIRECT", "IDLE"}


async def test_notifications_move_the_robot_and_its_scan_live(
    running: Running, fleet: Fleet
) -> None:
    await fleet.robot()
    await fleet.odometry(0.5, 0.5, 0.0)
    async with connect(running.ws_url) as ws:
        await next_message(ws, robot_update(ROBOT, lambda r: r["pose"] is not None))
        odom = await fleet.odometry(2.0, 1.0, 0.0, stamp=2.0)
        moved = await next_message(ws, robot_update(ROBOT, lambda r: r["pose"]["id"] == odom))
        assert (moved["robots"][ROBOT]["pose"]["x"], moved["robots"][ROBOT]["pose"]["y"]) == (
            2.0,
            1.0,
        )
        # a scan without an image is read from the table; drawn from the newest pose
        await fleet.scan([1.5, math.inf], stamp=2.0, image=False)
        seen = await next_message(ws, robot_update(ROBOT, lambda r: r["scan"] is not None))
        assert seen["robots"][ROBOT]["scan"]["points"] == [3.5, 1.0]
    # every notification went to the extra observers too
    tables = {note.table for note in running.observed}
    assert {keys.ROBOT, keys.ODOMETRY, keys.LASER_SCAN} <= tables


async def test_a_decision_is_shown_with_the_recommendations_it_weighed(
    running: Running, fleet: Fleet
) -> None:
    await fleet.robot()
    async with connect(running.ws_url) as ws:
        await next_message(ws, lambda m: m["type"] == "snapshot")
        odom = await fleet.odometry(1.0, 1.0, 0.0)
        scan = await fleet.scan([0.3, math.inf])
        drive = await fleet.recommendation("turn_then_move", 10, 0.2, {"odometry": odom})
        avoid = await fleet.recommendation("avoid_left", 50, 0.0, {"laser_scan": scan})
        decided = await fleet.decision(avoid, [drive, avoid], "avoid_left")
        message = await next_message(
            ws,
            robot_update(ROBOT, lambda r: (r["decision"] or {}).get("id") == decided),
        )
    decision = message["robots"][ROBOT]["decision"]
    assert decision["source"] == "avoid_left" and decision["recommendation_id"] == avoid
    # highest priority first, each with its reason and inputs
    assert [r["source"] for r in decision["considered"]] == ["avoid_left", "turn_then_move"]
    assert decision["considered"][0]["inputs"] == {"laser_scan": scan}
    assert decision["considered"][1]["reason"] == "turn_then_move says so"


async def test_goal_and_strategy_changes_reach_the_timeline(
    running: Running, fleet: Fleet, http: httpx.AsyncClient
) -> None:
    await fleet.robot()
    await eventually(lambda: running.dashboard.store.fleet.known(ROBOT), what="the robot")
    async with connect(running.ws_url) as ws:
        await next_message(ws, lambda m: m["type"] == "snapshot")
        response = await http.post(f"/api/robots/{ROBOT}/goal", json={"x": 1.5, "y": 0.5})
        assert response.status_code == 201, response.text
        goal_id = response.json()["goal_id"]
        event = await next_message(ws, lambda m: m["type"] == "timeline")
        assert event["events"][0]["key"] == f"goal:{goal_id}:active"
        assert event["events"][0]["text"] == f"goal {goal_id} (1.50, 0.50) set"
        cancelled = await http.delete(f"/api/robots/{ROBOT}/goal")
        assert cancelled.json() == {"robot": ROBOT, "cancelled": goal_id}
        event = await next_message(ws, lambda m: m["type"] == "timeline")
        assert event["events"][0]["text"].endswith("cancelled: cancelled by user")


async def test_a_planned_path_is_drawn_from_its_image_or_from_the_table(
    running: Running, fleet: Fleet, foreign: Runtime
) -> None:
    await fleet.robot()
    insert = (
        "INSERT INTO planned_path (robot_id, stamp, target, target_x, target_y, xs, ys, "
        "length_m) VALUES ($1, 2, 'charger', 0.5, 0.5, $2, $3, 1.4) RETURNING id"
    )
    async with connect(running.ws_url) as ws:
        await next_message(ws, lambda m: m["type"] == "snapshot")
        xs, ys = [1.5, 1.0, 0.5], [1.5, 1.0, 0.5]
        image = {"robot_id": ROBOT, "stamp": 2.0, "target": "charger", "target_x": 0.5}
        image |= {"target_y": 0.5, "xs": xs, "ys": ys, "length_m": 1.4, "goal_id": None}
        first = await fleet.write(keys.PLANNED_PATH, ROBOT, insert, ROBOT, xs, ys, image=image)
        seen = await next_message(ws, robot_update(ROBOT, lambda r: r["path"] is not None))
        assert seen["robots"][ROBOT]["path"]["id"] == first
        assert seen["robots"][ROBOT]["path"]["ys"] == ys
        # an image without the points is not used: the row is read instead
        partial = {"robot_id": ROBOT, "stamp": 3.0, "target": "none"}
        second = await fleet.write(
            keys.PLANNED_PATH, ROBOT, insert, ROBOT, [2.0], [2.5], image=partial
        )
        seen = await next_message(
            ws, robot_update(ROBOT, lambda r: (r["path"] or {}).get("id") == second)
        )
        assert seen["robots"][ROBOT]["path"]["xs"] == [2.0]
        assert seen["robots"][ROBOT]["path"]["target"] == "charger"  # as the row says
    assert await foreign.database.pool.fetchval("SELECT count(*) FROM planned_path") == 2


async def test_a_page_of_another_site_cannot_watch(running: Running) -> None:
    with pytest.raises(InvalidStatus) as refused:
        async with connect(running.ws_url, origin="http://evil.example"):  # type: ignore[arg-type]
            pass
    assert refused.value.response.status_code == 403

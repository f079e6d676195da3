"""The dashboard's HTTP and websocket endpoints (docs/DASHBOARD.md), as a Starlette app.

:func:`create_app` takes the store and the hub, plus ``extra_routes`` for what another part
of the service mounts on the same port (e.g. /metrics). Every refusal is JSON
``{"error": "<one line>"}`` with a 4xx status, and writes nothing.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Sequence
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

import asyncpg
from starlette.applications import Starlette
from starlette.exceptions import HTTPException
from starlette.middleware import Middleware
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, Response
from starlette.routing import BaseRoute, Mount, Route, WebSocketRoute
from starlette.staticfiles import StaticFiles
from starlette.websockets import WebSocket, WebSocketDisconnect

import services.dashboard.decision_provenance as provenance
from common.contract import keys, limits, zones
from common.errors import ConnectionFailure
from services.dashboard.gate import LOOPBACK_NAMES, AllowedHosts, Gate
from services.dashboard.hub import Hub
from services.dashboard.orders import Orders
from services.dashboard.requests import (
    MAX_BODY_BYTES,
    GoalRequest,
    NewStrategy,
    Refused,
    StrategyChoice,
    check_scenarios,
    json_object,
    zone_request,
)
from services.dashboard.store import DashboardStore

logger = logging.getLogger("pnav.dashboard.app")

STATIC = Path(__file__).resolve().parent / "static"
# how long POST .../strategy waits for the strategy service's verdict
VERDICT_WAIT_S = 5.0


def scenario_names() -> dict[str, list[str]]:
    """The scenarios installed here, by entry point name (none is imported: the dashboard
    only names them, the planner and controller services load them)."""
    return {
        family: sorted({p.name for p in entry_points(group=f"pnav.{family}.scenarios")})
        for family in ("planner", "controller")
    }


def refusal(status: int, reason: str) -> JSONResponse:
    return JSONResponse({"error": reason}, status_code=status)


class Endpoints:
    """The handlers, bound to one store and hub."""

    def __init__(self, store: DashboardStore, hub: Hub) -> None:
        self.store, self.hub = store, hub
        self.orders = Orders(store)

    @staticmethod
    async def body(request: Request) -> dict[str, Any]:
        """The request's JSON object, read no further than MAX_BODY_BYTES (413 past it)."""
        content_type = request.headers.get("content-type")
        declared = request.headers.get("content-length", "")
        if declared.isdigit() and int(declared) > MAX_BODY_BYTES:
            raise Refused(413, f"the body is over {MAX_BODY_BYTES} bytes")
        chunks, size = [], 0
        async for chunk in request.stream():
            size += len(chunk)
            if size > MAX_BODY_BYTES:
                raise Refused(413, f"the body is over {MAX_BODY_BYTES} bytes")
            chunks.append(chunk)
        return json_object(b"".join(chunks), content_type)

    @staticmethod
    def robot_of(request: Request) -> str:
        robot = str(request.path_params["robot"])
        if not keys.valid_id(robot):
            raise Refused(404, f"no robot {robot!r}: robot ids are letters, digits, _ and -")
        return robot

    async def index(self, request: Request) -> Response:
        return FileResponse(STATIC / "index.html")

    async def state(self, request: Request) -> Response:
        snapshot = self.store.snapshot()
        snapshot.pop("type")
        return JSONResponse(snapshot)

    async def strategies(self, request: Request) -> Response:
        return JSONResponse({"strategies": self.store.strategies, "scenarios": scenario_names()})

    async def set_goal(self, request: Request) -> Response:
        robot = self.robot_of(request)
        goal = GoalRequest.parse(await self.body(request))
        goal_id = await self.orders.set_goal(robot, goal)
        body = {"robot": robot, "goal_id": goal_id, "x": goal.x, "y": goal.y, "yaw": goal.yaw}
        body["waypoints"] = len(goal.waypoints)
        return JSONResponse(body, status_code=201)

    async def cancel_goal(self, request: Request) -> Response:
        robot = self.robot_of(request)
        return JSONResponse({"robot": robot, "cancelled": await self.orders.cancel_goal(robot)})

    async def set_strategy(self, request: Request) -> Response:
        robot = self.robot_of(request)
        choice = StrategyChoice.parse(await self.body(request))
        verdict = await self.orders.set_strategy(robot, choice.code, VERDICT_WAIT_S)
        status = 202 if verdict["status"] == "pending" else 200
        return JSONResponse({"robot": robot, "code": choice.code, **verdict}, status_code=status)

    async def add_strategy(self, request: Request) -> Response:
        new = NewStrategy.parse(await self.body(request))
        names = scenario_names()
        check_scenarios(new, set(names["planner"]), set(names["controller"]))
        await self.orders.add_strategy(new)
        return JSONResponse({"code": new.code}, status_code=201)

    async def zones(self, request: Request) -> Response:
        return JSONResponse({"zones": self.store.world.get("zones", [])})

    async def add_zone(self, request: Request) -> Response:
        zone = zone_request(await self.body(request))
        await self.orders.add_zone(zone)
        return JSONResponse(zone.image(), status_code=201)

    async def remove_zone(self, request: Request) -> Response:
        name = str(request.path_params["name"])
        if not zones.NAME.match(name):
            raise Refused(404, f"name: no zone {name[:80]!r}: names are [A-Za-z0-9_.-], 1 to 64")
        await self.orders.remove_zone(name)
        return JSONResponse({"name": name, "removed": True})

    async def decision(self, request: Request) -> Response:
        table = {"decisions": keys.COMMAND2ROBOT, "system-commands": keys.SYSTEM_COMMAND}
        kind = request.url.path.strip("/").split("/")[1]
        row_id = request.path_params["id"]
        if not 0 < row_id <= limits.MAX_INT64:
            raise Refused(404, f"no {table[kind]} row {str(row_id)[:30]}: ids are 64-bit")
        return JSONResponse(await provenance.provenance(self.store.source, table[kind], row_id))

    async def websocket(self, websocket: WebSocket) -> None:
        # its Host and Origin were checked at the gate (services.dashboard.gate)
        await websocket.accept()
        browser = self.hub.join(self.store.snapshot())
        reader = asyncio.create_task(_drain(websocket), name="ws-reader")
        try:
            while True:
                getter = asyncio.ensure_future(browser.queue.get())
                done, _ = await asyncio.wait({getter, reader}, return_when=asyncio.FIRST_COMPLETED)
                if getter not in done:
                    getter.cancel()
                    break
                text = getter.result()
                if text is None:
                    await websocket.close(code=1013)  # try again later: reconnect
                    break
                await websocket.send_text(text)
        except (WebSocketDisconnect, RuntimeError, OSError):
            pass  # the browser went away mid-send
        finally:
            self.hub.leave(browser)
            reader.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await reader


async def _drain(websocket: WebSocket) -> None:
    """Read (and ignore) what the browser sends, until it disconnects: the page writes
    through the HTTP endpoints, the websocket only pushes."""
    with contextlib.suppress(WebSocketDisconnect):
        while True:
            message = await websocket.receive()
            if message["type"] == "websocket.disconnect":
                return


async def _refused(request: Request, exc: Exception) -> Response:
    assert isinstance(exc, Refused)
    return refusal(exc.status, exc.reason)


async def _http_error(request: Request, exc: Exception) -> Response:
    assert isinstance(exc, HTTPException)
    return refusal(exc.status_code, str(exc.detail))


async def _unreachable(request: Request, exc: Exception) -> Response:
    logger.warning("the database is unreachable: %s", exc)
    return refusal(503, f"the contract database is unreachable now: {exc}")


def create_app(
    store: DashboardStore,
    hub: Hub,
    extra_routes: Sequence[BaseRoute] = (),
    allowed: AllowedHosts | None = None,
) -> Starlette:
    """The app; ``allowed``: the Host names it answers (loopback only by default)."""
    api = Endpoints(store, hub)
    routes: list[BaseRoute] = [
        Route("/", api.index),
        Route("/api/state", api.state),
        Route("/api/strategies", api.strategies),
        Route("/api/strategies", api.add_strategy, methods=["POST"]),
        Route("/api/robots/{robot}/goal", api.set_goal, methods=["POST"]),
        Route("/api/robots/{robot}/goal", api.cancel_goal, methods=["DELETE"]),
        Route("/api/robots/{robot}/strategy", api.set_strategy, methods=["POST"]),
        Route("/api/zones", api.zones),
        Route("/api/zones", api.add_zone, methods=["POST"]),
        Route("/api/zones/{name}", api.remove_zone, methods=["DELETE"]),
        Route("/api/decisions/{id:int}", api.decision),
        Route("/api/system-commands/{id:int}", api.decision),
        WebSocketRoute("/ws", api.websocket),
        *extra_routes,
        Mount("/static", StaticFiles(directory=STATIC), name="static"),
    ]
    handlers: dict[Any, Any] = {
        Refused: _refused,
        HTTPException: _http_error,
        ConnectionFailure: _unreachable,
        OSError: _unreachable,
        asyncpg.PostgresConnectionError: _unreachable,
        asyncpg.InterfaceError: _unreachable,
    }
    gate = Middleware(Gate, allowed=allowed or AllowedHosts(frozenset(LOOPBACK_NAMES)))
    return Starlette(routes=routes, exception_handlers=handlers, middleware=[gate])

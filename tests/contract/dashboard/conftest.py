"""Fixtures for the dashboard's contract tests: the dashboard alone, on the current loop,
serving on a free loopback port, with a foreign client writing the rows it shows.

``fleet`` plays every other party: it writes robot, map, charging_station, sensor,
recommendation and decision rows with plain SQL and publishes their notifications (with
row images where the contract's writers send them) through a plain ``bus.Notifier``.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Any

import httpx
import pytest
from starlette.routing import Route

from common.bus import Notification
from common.config import ServiceConfig, ZenohSettings
from common.contract import keys
from common.runtime import Runtime
from pnav._testing import eventually
from services.dashboard.service import Dashboard
from services.dashboard.settings import DashboardSettings

ROBOT = "r1"


@dataclass
class Running:
    dashboard: Dashboard
    url: str
    observed: list[Notification]

    @property
    def ws_url(self) -> str:
        return self.url.replace("http://", "ws://") + "/ws"


class Fleet:
    """Rows as the bridge, the planner, the controllers and the decision write them."""

    def __init__(self, runtime: Runtime) -> None:
        self.db = runtime.database

    async def write(
        self, table: str, robot: str | None, sql: str, *args: Any, image: dict[str, Any] | None
    ) -> Any:
        return await self.db.write(table, robot, sql, *args, image=image)

    async def robot(self, robot: str = ROBOT) -> None:
        await self.write(
            keys.ROBOT, robot, "INSERT INTO robot (robot_id) VALUES ($1)", robot, image=None
        )

    async def world(self) -> None:
        """A 4 x 2 m map at 0.5 m per cell (an obstacle in cell (1, 0)) and one charger."""
        grid = bytes([0, 100, 0, 0, 0, 0, 0, 255])
        await self.write(
            keys.MAP,
            None,
            "INSERT INTO map (map_id, resolution_m, origin_x, origin_y, origin_yaw, width, "
            "height, grid, source) VALUES ('room', 0.5, 0, 0, 0, 4, 2, $1, 'test')",
            grid,
            image=None,
        )
        await self.write(
            keys.CHARGING_STATION,
            None,
            "INSERT INTO charging_station (station_id, map_id, x, y, radius_m, charge_power_w) "
            "VALUES ('dock', 'room', 0.5, 0.5, 0.3, 20)",
            image=None,
        )

    async def odometry(self, x: float, y: float, yaw: float, stamp: float = 1.0) -> int:
        image = {"robot_id": ROBOT, "stamp": stamp, "seq": 1, "x": x, "y": y, "yaw": yaw}
        image |= {"linear_mps": 0.1, "angular_rps": 0.0}
        return int(
            await self.write(
                keys.ODOMETRY,
                ROBOT,
                "INSERT INTO odometry (robot_id, stamp, seq, x, y, yaw, linear_mps, angular_rps) "
                "VALUES ($1, $2, 1, $3, $4, $5, 0.1, 0) RETURNING id",
                ROBOT,
                stamp,
                x,
                y,
                yaw,
                image=image,
            )
        )

    async def scan(self, ranges: list[float], stamp: float = 1.0, image: bool = True) -> int:
        values = {"robot_id": ROBOT, "stamp": stamp, "seq": 1, "angle_min": 0.0}
        values |= {"angle_increment": 2 * 3.141592653589793 / len(ranges)}
        values |= {"range_min": 0.12, "range_max": 3.5, "ranges": ranges}
        return int(
            await self.write(
                keys.LASER_SCAN,
                ROBOT,
                "INSERT INTO laser_scan (robot_id, stamp, seq, angle_min, angle_increment, "
                "range_min, range_max, ranges) VALUES ($1, $2, 1, 0, $3, 0.12, 3.5, $4) "
                "RETURNING id",
                ROBOT,
                stamp,
                values["angle_increment"],
                ranges,
                image=values if image else None,
            )
        )

    async def recommendation(
        self, source: str, priority: int, linear: float, inputs: dict[str, Any]
    ) -> int:
        return int(
            await self.write(
                keys.COMMAND_RECOMMENDATION,
                ROBOT,
                "INSERT INTO command_recommendation (robot_id, kind, source, priority, "
                "linear_mps, angular_rps, stamp, expires_stamp, inputs, reason) "
                "VALUES ($1, 'robot', $2, $3, $4, 0.5, 1.0, 1.5, $5, $6) RETURNING id",
                ROBOT,
                source,
                priority,
                linear,
                inputs,
                f"{source} says so",
                image=None,
            )
        )

    async def decision(self, winner: int, considered: list[int], source: str) -> int:
        image = {"robot_id": ROBOT, "stamp": 1.0, "linear_mps": 0.0, "angular_rps": 0.5}
        image |= {"recommendation_id": winner, "source": source}
        image |= {"considered_ids": considered, "reason": "highest priority"}
        return int(
            await self.write(
                keys.COMMAND2ROBOT,
                ROBOT,
                "INSERT INTO command2robot (robot_id, stamp, linear_mps, angular_rps, "
                "recommendation_id, source, considered_ids, reason) "
                "VALUES ($1, 1.0, 0, 0.5, $2, $3, $4, 'highest priority') RETURNING id",
                ROBOT,
                winner,
                source,
                considered,
                image=image,
            )
        )


@pytest.fixture
async def foreign(db_url: str, zenoh_settings: ZenohSettings) -> AsyncIterator[Runtime]:
    runtime = await Runtime.open(
        ServiceConfig(service="tester", database_url=db_url, zenoh=zenoh_settings)
    )
    try:
        yield runtime
    finally:
        await runtime.close()


@pytest.fixture
def fleet(foreign: Runtime) -> Fleet:
    return Fleet(foreign)


async def extra(request: Any) -> Any:
    from starlette.responses import PlainTextResponse

    return PlainTextResponse("mounted")


@asynccontextmanager
async def serving(
    db_url: str, zenoh_settings: ZenohSettings, settings: DashboardSettings | None = None
) -> AsyncIterator[Running]:
    """The dashboard as ``running`` serves it, with ``settings`` (a free port by default)."""
    config = ServiceConfig(
        service="dashboard", database_url=db_url, zenoh=zenoh_settings, instance="dashboard-1"
    )
    runtime = await Runtime.open(config)
    observed: list[Notification] = []
    dashboard = Dashboard(
        runtime,
        settings or DashboardSettings(port=0, push_period_s=0.05),
        extra_routes=[Route("/extra", extra)],
        observers=[observed.append],
    )
    stop = asyncio.Event()
    task = asyncio.create_task(dashboard.run(stop))
    try:
        await eventually(
            lambda: dashboard.port != 0 and dashboard.store.loaded.is_set(),
            within=20,
            what="the dashboard to listen and read the tables",
        )
        await asyncio.sleep(0.3)  # its subscription reaches the router
        yield Running(dashboard, f"http://127.0.0.1:{dashboard.port}", observed)
    finally:
        stop.set()
        try:
            await asyncio.wait_for(task, 15)
        finally:
            await runtime.close()


@pytest.fixture
async def running(db_url: str, zenoh_settings: ZenohSettings) -> AsyncIterator[Running]:
    async with serving(db_url, zenoh_settings) as served:
        yield served


@pytest.fixture
async def http(running: Running) -> AsyncIterator[httpx.AsyncClient]:
    async with httpx.AsyncClient(base_url=running.url, timeout=20) as client:
        yield client


def body(response: httpx.Response) -> dict[str, Any]:
    value: dict[str, Any] = json.loads(response.text)
    return value

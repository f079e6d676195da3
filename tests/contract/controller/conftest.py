"""The controller under test, and a foreign client that feeds it as the bridge, the strategy
service and the sim would: plain SQL, a change notification after each write, sim time on
``pnav/sim/clock``. Tests assert on table contents only, so another implementation of the
controller that speaks the contract passes them by swapping the ``controller`` fixture.

The ``controller`` fixture runs every test that asks for it twice: against the shipped
controller (in-process), and against ``examples/sql_controller`` (docs/SWAP.md), started as
a real process the way a compose container starts it: ``python -m examples.sql_controller``
with only PNAV_* variables for this test's Postgres and loopback router, ready once its
liveliness token is up and it holds every robot's lease, stopped with SIGTERM and expected
to exit 0.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import signal
import socket
import sys
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path
from typing import Any, TypeVar

import asyncpg
import pytest

from common import bus
from common.config import EngineSettings, ServiceConfig, ZenohSettings
from common.contract import keys
from common.db import connect
from pnav._testing import as_service_role, publish_clock, running_service

T = TypeVar("T")

SIM_START = 100.0
ROBOT = "r1"
BEAMS = 360
Obstacle = tuple[float, float, float]  # (from deg, to deg, range m), in (-180, 180], CCW


ROOT = Path(__file__).resolve().parents[3]
IMPLEMENTATIONS = ("shipped", "sql_controller")


@pytest.fixture(params=IMPLEMENTATIONS)
async def controller(
    request: pytest.FixtureRequest, db_url: str, zenoh_settings: ZenohSettings, tmp_path: Path
) -> AsyncIterator[None]:
    """A controller, running until the test ends: the shipped one, then the example; both
    as the controller's Postgres role (exactly its grants)."""
    role_url = await as_service_role(db_url, "controller")
    if request.param == "sql_controller":
        async with example_controller(role_url, zenoh_settings, tmp_path / "sql_controller.log"):
            yield
        return
    from services.controller.service import ControllerService

    config = ServiceConfig(
        service="controller",
        database_url=role_url,
        zenoh=zenoh_settings,
        engine=EngineSettings(period_s=0.05),
        stats_period_s=30.0,
        instance="controller-under-test",
    )
    async with running_service(ControllerService, config, settle_s=0.5):
        yield


def compose_like_env(db_url: str, zenoh_settings: ZenohSettings) -> dict[str, str]:
    """What deploy/docker-compose.yml gives a controller container, pointed at this test's
    Postgres and router; no other PNAV_* variable (PNAV_INSTANCE unset, as there)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("PNAV_")}
    env.update(
        PNAV_DATABASE_URL=db_url,
        PNAV_ZENOH_MODE="client",
        PNAV_ZENOH_CONNECT=",".join(zenoh_settings.connect),
        PNAV_ZENOH_MULTICAST="false",
        PNAV_LOG_LEVEL="INFO",
        # not from compose: if this test process dies, the example dies with it
        PNAV_PARENT_PID=str(os.getpid()),
    )
    return env


@contextlib.asynccontextmanager
async def example_controller(
    db_url: str, zenoh_settings: ZenohSettings, log: Path
) -> AsyncIterator[None]:
    """``python -m examples.sql_controller`` from the repository root, until SIGTERM."""
    async with controller_process("examples.sql_controller", db_url, zenoh_settings, log):
        yield


@contextlib.asynccontextmanager
async def controller_process(
    module: str,
    db_url: str,
    zenoh_settings: ZenohSettings,
    log: Path,
    python_path: Path | None = None,
) -> AsyncIterator[None]:
    """``python -m <module>`` from the repository root (``python_path`` on PYTHONPATH, as
    an installed package's directory would be), ready as :func:`example_ready` says, until
    SIGTERM; it must exit 0."""
    env = compose_like_env(db_url, zenoh_settings)
    if python_path is not None:
        env["PYTHONPATH"] = os.pathsep.join(
            p for p in (str(python_path), env.get("PYTHONPATH")) if p
        )
    with log.open("wb") as sink:
        process = await asyncio.create_subprocess_exec(
            sys.executable,
            "-m",
            module,
            cwd=ROOT,
            env=env,
            stdin=asyncio.subprocess.DEVNULL,
            stdout=sink,
            stderr=sink,
        )
    try:
        await example_ready(process, db_url, zenoh_settings, log)
        yield
    finally:
        if process.returncode is None:
            process.send_signal(signal.SIGTERM)
            try:
                await asyncio.wait_for(process.wait(), 20)
            except TimeoutError:
                process.kill()
                await process.wait()
    assert process.returncode == 0, f"exit {process.returncode}:\n{tail(log)}"


def tail(log: Path) -> str:
    """The end of the process's log, for a failure message."""
    return log.read_text(errors="replace")[-3000:]


async def example_ready(
    process: asyncio.subprocess.Process, db_url: str, zenoh_settings: ZenohSettings, log: Path
) -> None:
    """Its liveliness token is up (it declares it last) and it holds every robot's lease
    (the example, or any controller process started by :func:`controller_process`)."""
    conn = await connect(db_url)
    session = await asyncio.to_thread(bus.open_session, zenoh_settings)
    # PNAV_INSTANCE is unset, so it must announce itself as <hostname>-<pid>
    instance = f"{socket.gethostname()}-{process.pid}".replace(".", "-")
    token = keys.alive_key("controller", instance)

    def token_up() -> bool:
        replies = session.liveliness().get(token, timeout=1)
        return any(reply.ok is not None for reply in replies)

    async def ready() -> bool:
        if process.returncode is not None:
            raise AssertionError(f"it exited {process.returncode}:\n{tail(log)}")
        if not await asyncio.to_thread(token_up):
            return False
        unleased = await conn.fetchval(
            "SELECT count(*) FROM robot r WHERE NOT EXISTS (SELECT 1 FROM robot_lease l "
            "WHERE l.service = 'controller' AND l.robot_id = r.robot_id AND l.released_at IS NULL)"
        )
        return unleased == 0

    try:
        await eventually(ready, "the controller process to be ready", 30.0)
    finally:
        await conn.close()
        await asyncio.to_thread(session.close)


class Feeder:
    """Writes what the controller reads about ``robot``, as a client in any language would."""

    def __init__(self, conn: asyncpg.Connection, session: Any, robot: str = ROBOT) -> None:
        self.conn = conn
        self.session = session
        self.robot = robot
        self.notifier = bus.Notifier(session)
        self.started = time.monotonic()

    def now(self) -> float:
        """Sim time: runs at rate 1 from SIM_START."""
        return SIM_START + (time.monotonic() - self.started)

    async def run_clock(self) -> None:
        while True:  # the sim publishes its clock at 20 Hz or more
            publish_clock(self.session, self.now())
            await asyncio.sleep(0.05)

    async def add_robot(self) -> None:
        await self.conn.execute(
            "INSERT INTO robot (robot_id, world) VALUES ($1, 'test')", self.robot
        )
        self.notifier.notify(keys.ROBOT, self.robot, None)

    async def set_strategy(self, code: str) -> None:
        await self.conn.execute(
            "INSERT INTO active_strategy (robot_id, strategy_code, source, stamp) "
            "VALUES ($1, $2, 'user', $3) ON CONFLICT (robot_id) DO UPDATE SET "
            "strategy_code = EXCLUDED.strategy_code, source = 'user', stamp = EXCLUDED.stamp, "
            "updated_at = now()",
            self.robot,
            code,
            self.now(),
        )
        self.notifier.notify(keys.ACTIVE_STRATEGY, self.robot, None)

    async def add_strategy(self, code: str, scenarios: list[str], params: dict[str, Any]) -> None:
        await self.conn.execute(
            "INSERT INTO strategy (code, planner_scenario, controller_scenarios, params) "
            "VALUES ($1, NULL, $2, $3)",
            code,
            scenarios,
            params,
        )
        self.notifier.notify(keys.STRATEGY, None, None)

    async def odometry(self, linear: float, angular: float = 0.0) -> int:
        row_id: int = await self.conn.fetchval(
            "INSERT INTO odometry (robot_id, stamp, x, y, yaw, linear_mps, angular_rps) "
            "VALUES ($1, $2, 0, 0, 0, $3, $4) RETURNING id",
            self.robot,
            self.now(),
            linear,
            angular,
        )
        self.notifier.notify(keys.ODOMETRY, self.robot, row_id)
        return row_id

    async def scan(self, *obstacles: Obstacle, age_s: float = 0.0, notify: bool = True) -> int:
        """A 360-beam sweep (beam 0 ahead, CCW), inf except the obstacles; returns its id.
        ``notify`` False: no notification (the caller sends one for several robots)."""
        ranges = [math.inf] * BEAMS
        for beam in range(BEAMS):
            angle = beam if beam <= 180 else beam - 360
            for low, high, distance in obstacles:
                if low <= angle <= high:
                    ranges[beam] = min(ranges[beam], distance)
        row_id: int = await self.conn.fetchval(
            "INSERT INTO laser_scan (robot_id, stamp, angle_min, angle_increment, range_min, "
            "range_max, ranges) VALUES ($1, $2, 0, $3, 0.12, 3.5, $4) RETURNING id",
            self.robot,
            self.now() - age_s,
            2 * math.pi / BEAMS,
            ranges,
        )
        if notify:
            self.notifier.notify(keys.LASER_SCAN, self.robot, row_id)
        return row_id

    async def recommendations(self, *sources: str) -> list[asyncpg.Record]:
        return list(
            await self.conn.fetch(
                "SELECT * FROM command_recommendation WHERE robot_id = $1 "
                "AND (cardinality($2::text[]) = 0 OR source = ANY($2)) ORDER BY id",
                self.robot,
                list(sources),
            )
        )

    async def sources_for(self, scan_id: int) -> set[str]:
        rows = await self.conn.fetch(
            "SELECT source FROM command_recommendation WHERE (inputs->>'laser_scan')::bigint = $1",
            scan_id,
        )
        return {r["source"] for r in rows}


@pytest.fixture
async def feeder(db_url: str, zenoh_settings: ZenohSettings) -> AsyncIterator[Feeder]:
    conn = await connect(db_url)
    session = await asyncio.to_thread(bus.open_session, zenoh_settings)
    feed = Feeder(conn, session)
    clock = asyncio.create_task(feed.run_clock())
    try:
        await feed.add_robot()
        yield feed
    finally:
        clock.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await clock
        feed.notifier.close()
        await conn.close()
        await asyncio.to_thread(session.close)


async def eventually(
    check: Callable[[], Awaitable[T | None]], what: str, limit_s: float = 15.0
) -> T:
    """Poll ``check`` until it returns something truthy; fail after ``limit_s``."""
    deadline = time.monotonic() + limit_s
    while True:
        result = await check()
        if result:
            return result
        if time.monotonic() > deadline:
            raise AssertionError(f"not within {limit_s} s: {what}")
        await asyncio.sleep(0.05)

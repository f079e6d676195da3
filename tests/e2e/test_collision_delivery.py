"""A collision event is never lost: one that happens while the router between sim and bridge
is frozen reaches ``collision_event`` once the router is back, as exactly one row."""

from __future__ import annotations

import asyncio
import signal
import subprocess
import threading
from collections.abc import Iterator
from pathlib import Path

import asyncpg
import pytest

from common import bus
from common.config import ServiceConfig, ZenohSettings
from common.contract import keys
from common.runtime import Runtime
from pnav._testing import eventually, router_process
from services.bridge import Bridge, BridgeSettings
from services.sim.node import SimNode
from services.sim.sim import SimConfig
from services.sim.world_spec import load_world

pytestmark = pytest.mark.timeout(120)

ROOT = Path(__file__).resolve().parents[2]
OPEN_ROOM = ROOT / "worlds" / "open_room.yaml"  # r1 at (1, 1) facing +x: a wall 1 m behind


@pytest.fixture
def router() -> Iterator[tuple[subprocess.Popen[str], ZenohSettings]]:
    with router_process() as (proc, settings):
        yield proc, settings


async def rows(url: str) -> list[asyncpg.Record]:
    conn = await asyncpg.connect(url)
    try:
        found: list[asyncpg.Record] = await conn.fetch(
            "SELECT robot_id, other, seq, run FROM collision_event"
        )
        return found
    finally:
        await conn.close()


async def test_a_collision_during_a_router_freeze_is_one_row_after_it(
    router: tuple[subprocess.Popen[str], ZenohSettings], db_url: str
) -> None:
    proc, settings = router
    sim_session = await asyncio.to_thread(bus.open_session, settings)
    # no command timeout: the test drives the sim directly while the router is frozen
    node = SimNode(load_world(OPEN_ROOM), SimConfig(cmd_timeout_s=0), sim_session, rate=4.0)
    stop = threading.Event()
    loop = threading.Thread(target=node.run, args=(stop,), daemon=True)
    runtime = await Runtime.open(
        ServiceConfig(service="bridge", database_url=db_url, zenoh=settings, instance="t-bridge")
    )
    bridge = Bridge(runtime, BridgeSettings(world_retry_s=0.5))
    frozen = False
    try:
        loop.start()
        await bridge.start()
        await eventually(lambda: "r1" in bridge.robots, 30, what="the world")
        await eventually(lambda: bridge.counters.rows_written[keys.ODOMETRY] > 0, 30, what="odom")

        proc.send_signal(signal.SIGSTOP)
        frozen = True
        sim = node.sim
        # backwards into the wall behind: the contact happens while nothing gets through
        sim.set_command("r1", -0.22, 0.0)
        await eventually(lambda: sim.counts[keys.COLLISION] >= 1, 30, what="the contact")
        sim.set_command("r1", 0.0, 0.0)
        # the sim keeps the event and sends it again; none of it can arrive yet
        await eventually(lambda: node.outbox.resent >= 2, 10, what="resends")
        assert node.outbox.waiting() == 1
        assert await rows(db_url) == []

        proc.send_signal(signal.SIGCONT)
        frozen = False
        await eventually(lambda: node.outbox.waiting() == 0, 30, what="the acknowledgement")
        got = await rows(db_url)
        assert [(r["robot_id"], r["seq"], r["run"]) for r in got] == [("r1", 0, node.outbox.run)]
        assert got[0]["other"]  # what it touched, named
        assert sim.counts[keys.COLLISION] == 1  # one contact, however many copies were sent
        # every copy that did arrive (the first, held in the frozen link, and resends) was
        # acknowledged and none made a second row
        counters = bridge.counters
        await eventually(
            lambda: counters.collision_acks == counters.messages_in[keys.COLLISION] >= 1,
            10,
            what="every copy received acknowledged",
        )
        assert len(await rows(db_url)) == 1
    finally:
        if frozen:
            proc.send_signal(signal.SIGCONT)
        stop.set()
        await asyncio.to_thread(loop.join, 10)
        await bridge.stop()
        await runtime.close()
        node.close()
        sim_session.close()

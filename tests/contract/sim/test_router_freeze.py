"""The hostile case the sim's command timeout is for: the Zenoh router freezes while a robot
drives. Nothing the bridge sends can get through then, its watchdog's stop included; the
robot must stop by itself, 0.5 s of sim time after its last command, and drive again when
the commands come back."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from common.bus import open_session, pack
from common.config import ZenohSettings
from common.contract import keys
from pnav.run.embedded_postgres import free_port
from services.sim.node import SimNode
from services.sim.sim import SimConfig
from services.sim.world_spec import load_world

pytestmark = pytest.mark.timeout(60)

ROOT = Path(__file__).resolve().parents[3]
OPEN_ROOM = ROOT / "worlds" / "open_room.yaml"  # r1 at (1, 1) facing +x, 4 m of floor ahead
DT = 1.0 / 240.0

ROUTER = (
    "import sys, time\n"
    "from common.bus import start_router\n"
    "router = start_router((sys.argv[1],))\n"
    "print('up', flush=True)\n"
    "time.sleep(3600)\n"
)


@pytest.fixture
def router() -> Iterator[tuple[subprocess.Popen[str], ZenohSettings]]:
    """A Zenoh router in its own process, so that it can be frozen (SIGSTOP)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    proc = subprocess.Popen(
        [sys.executable, "-c", ROUTER, endpoint],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "up"
        yield proc, ZenohSettings(mode="client", connect=(endpoint,))
    finally:
        proc.send_signal(signal.SIGCONT)
        proc.kill()
        proc.wait()


def test_a_frozen_router_stops_the_robot_within_half_a_second_of_sim_time(
    router: tuple[subprocess.Popen[str], ZenohSettings],
) -> None:
    proc, settings = router
    sim_session, driver = open_session(settings), open_session(settings)
    node = SimNode(load_world(OPEN_ROOM), SimConfig(), sim_session, rate=1.0)
    stop, sending = threading.Event(), threading.Event()
    loop = threading.Thread(target=node.run, args=(stop,), daemon=True)

    def drive() -> None:
        # the bridge relaying the decision service's re-issues, every 0.1 s; it goes on
        # while the router is frozen: its messages just do not arrive
        key = keys.robot_key("r1", keys.CMD_VEL)
        while sending.is_set():
            body = {"stamp": node.sim.time, "linear": 0.2, "angular": 0.0, "command_id": 1}
            driver.put(key, pack(body))
            time.sleep(0.1)

    sender = threading.Thread(target=drive, daemon=True)
    robot = node.sim.robots[0]
    try:
        loop.start()
        sending.set()
        sender.start()
        deadline = time.monotonic() + 10.0
        while robot.x < 1.1 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert robot.x >= 1.1 and robot.linear == pytest.approx(0.2)  # driving

        proc.send_signal(signal.SIGSTOP)
        frozen_at, x_frozen = node.sim.time, robot.x
        time.sleep(2.0)
        assert node.sim.time > frozen_at + 1.5  # the sim ran on meanwhile
        x_after = robot.x
        assert robot.linear == 0.0 and node.sim.cmd_timeout_stops == 1
        # the last command arrived before the freeze: at most 0.5 s more on it (and a step),
        # then the motors brake at the model's deceleration (v^2 / 2a more)
        braking = 0.2**2 / (2 * robot.model.max_linear_accel_mps2)
        assert x_after - x_frozen <= 0.2 * (0.5 + DT) + braking + 1e-9
        # without the timeout it would have driven on for the whole freeze
        assert x_after - x_frozen < 0.2 * (node.sim.time - frozen_at) / 2

        proc.send_signal(signal.SIGCONT)
        deadline = time.monotonic() + 10.0
        while robot.x < x_after + 0.05 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert robot.x >= x_after + 0.05  # the commands came back: it drives again
    finally:
        proc.send_signal(signal.SIGCONT)
        sending.clear()
        stop.set()
        loop.join(10)
        sender.join(5)
        node.close()
        driver.close()
        sim_session.close()
    assert not loop.is_alive()

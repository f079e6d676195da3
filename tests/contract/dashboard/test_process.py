"""``python -m services.dashboard`` as the supervisor and compose run it: serves, stops
cleanly on SIGTERM, and says why when it cannot run."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time

import httpx
import pytest

from common.config import ZenohSettings
from pnav.run.embedded_postgres import free_port

pytestmark = pytest.mark.timeout(90)


def service_env(db_url: str, zenoh: ZenohSettings, port: int) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("PNAV_")}
    return {
        **env,
        **zenoh.to_env(),
        "PNAV_DATABASE_URL": db_url,
        "PNAV_DASHBOARD_PORT": str(port),
    }


def start(env: dict[str, str]) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "services.dashboard"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )


def test_it_serves_until_sigterm_then_exits_0(db_url: str, zenoh_settings: ZenohSettings) -> None:
    port = free_port()
    process = start(service_env(db_url, zenoh_settings, port))
    try:
        deadline = time.monotonic() + 60
        while True:
            assert process.poll() is None, process.communicate()[1][-2000:]
            try:
                response = httpx.get(f"http://127.0.0.1:{port}/api/state", timeout=5)
                if response.status_code == 200:
                    break
            except httpx.TransportError:
                pass
            assert time.monotonic() < deadline, "the dashboard never answered"
            time.sleep(0.2)
        assert {"world", "robots", "strategies", "timeline"} <= set(response.json())
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=20) == 0, process.communicate()[1][-2000:]
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


def test_a_port_in_use_is_exit_1_saying_so(db_url: str, zenoh_settings: ZenohSettings) -> None:
    port = free_port()
    with socket.create_server(("127.0.0.1", port)):
        process = start(service_env(db_url, zenoh_settings, port))
        _out, err = process.communicate(timeout=60)
    assert process.returncode == 1, err
    assert f"the dashboard cannot listen on 127.0.0.1:{port}" in err


def test_a_bad_port_setting_is_exit_2_naming_the_variable(
    db_url: str, zenoh_settings: ZenohSettings
) -> None:
    env = service_env(db_url, zenoh_settings, 0) | {"PNAV_DASHBOARD_PORT": "eighty"}
    process = start(env)
    _out, err = process.communicate(timeout=60)
    assert process.returncode == 2, err
    assert "PNAV_DASHBOARD_PORT='eighty' is not a port number" in err

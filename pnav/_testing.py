"""Real infrastructure for tests and benchmarks: loopback Zenoh, services run in process.

Private to the repository's own tests and benchmarks (the leading underscore): no service,
plug-in or command imports it. Nothing here is mocked: :func:`loopback_zenoh` runs an
in-process router with multicast scouting off, :func:`router_process` one in a process of its
own; the embedded Postgres and :func:`free_port` are the local stack's own
(pnav/run/embedded_postgres.py), re-used here.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from common.config import ServiceConfig, ZenohSettings
from pnav.run.embedded_postgres import free_port

if TYPE_CHECKING:
    from common.service import ScenarioService


@contextlib.contextmanager
def loopback_zenoh() -> Iterator[ZenohSettings]:
    """Run a Zenoh router on a free loopback port; yield the settings clients use."""
    from common.bus import start_router

    last_error: Exception | None = None
    for _ in range(5):
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        try:
            router = start_router((endpoint,))
        except Exception as exc:  # the port was taken in between: pick another
            last_error = exc
            continue
        try:
            yield ZenohSettings(mode="client", connect=(endpoint,))
        finally:
            router.close()
        return
    raise RuntimeError(f"could not start a loopback Zenoh router: {last_error}")


_ROUTER = (
    "import os, sys, time\n"
    "from common.bus import start_router\n"
    "router = start_router((sys.argv[1],), os.environ.get('PNAV_ZENOH_USERS_FILE') or None)\n"
    "print('up', flush=True)\n"
    "time.sleep(1e6)\n"
)


@contextlib.contextmanager
def router_process(
    users_file: str | Path | None = None,
) -> Iterator[tuple[subprocess.Popen[str], ZenohSettings]]:
    """A loopback Zenoh router in a process of its own, so that it alone can be frozen
    (SIGSTOP/SIGCONT) or killed; yield the process and the settings clients use. With
    ``users_file`` it accepts only sessions of a user/password in that file."""
    import signal
    import sys

    root = Path(__file__).resolve().parents[1]
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    proc = subprocess.Popen(
        [sys.executable, "-c", _ROUTER, endpoint],
        cwd=root,
        stdout=subprocess.PIPE,
        text=True,
        env={
            **os.environ,
            "PNAV_ZENOH_USERS_FILE": str(users_file or ""),
            "PYTHONPATH": str(root),
        },
    )
    try:
        if proc.stdout is None or proc.stdout.readline().strip() != "up":
            raise RuntimeError("the Zenoh router process did not start")
        yield proc, ZenohSettings(mode="client", connect=(endpoint,))
    finally:
        with contextlib.suppress(ProcessLookupError):
            proc.send_signal(signal.SIGCONT)
        proc.kill()
        proc.wait()


@contextlib.contextmanager
def acl_router(
    config_file: str | Path, passwords: Mapping[str, str], directory: str | Path
) -> Iterator[str]:
    """Run the router of ``config_file`` (deploy/zenoh/router.json5: its access control and
    user/password authentication) in this process on a free loopback port, its dictionary
    written to ``directory`` from ``passwords`` (user -> password); yield the endpoint."""
    import json

    import zenoh

    dictionary = Path(directory) / "zenoh-users.txt"
    dictionary.write_text("".join(f"{user}:{pw}\n" for user, pw in passwords.items()))
    config = zenoh.Config.from_file(str(config_file))
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    config.insert_json5("listen/endpoints", json.dumps([endpoint]))
    config.insert_json5("transport/auth/usrpwd/dictionary_file", json.dumps(str(dictionary)))
    router = zenoh.open(config)
    try:
        yield endpoint
    finally:
        router.close()


async def as_service_role(db_url: str, service: str) -> str:
    """``db_url`` set up with the roles, as ``pnav up`` and the compose migration do
    (common.contract.roles.bootstrap, as the superuser ``db_url`` names), then the DSN of
    ``service``'s role: a contract test runs the service with exactly its grants. The test
    server trusts its local socket, so no password."""
    import asyncpg

    from common.contract.grants import role_name
    from common.contract.roles import bootstrap, role_url

    conn = await asyncpg.connect(db_url)
    try:
        await bootstrap(conn)
    finally:
        await conn.close()
    return role_url(db_url, role_name(service), None)


@contextlib.asynccontextmanager
async def running_service(
    service_cls: type[ScenarioService], config: ServiceConfig, settle_s: float = 0.3
) -> AsyncIterator[ScenarioService]:
    """Run a scenario service on the current loop, as its process would; stop and drain it
    on exit. ``settle_s`` lets its subscriptions reach the router before the test writes."""
    import asyncio

    from common.runtime import Runtime

    runtime = await Runtime.open(config)
    service = service_cls(runtime)
    stop = asyncio.Event()
    task = asyncio.create_task(service.run(stop))
    try:
        await asyncio.sleep(settle_s)
        yield service
    finally:
        stop.set()
        try:
            await asyncio.wait_for(task, 15)
        finally:
            await runtime.close()


def publish_clock(session: Any, stamp: float, rate: float = 1.0) -> None:
    """Publish sim time as the sim does (for tests that play the sim's part)."""
    from common import bus
    from common.contract import keys

    session.put(keys.SIM_CLOCK, bus.pack({"stamp": stamp, "rate": rate}))


async def eventually(
    check: Callable[[], Any], within: float = 10.0, interval: float = 0.02, what: str = ""
) -> Any:
    """Wait until ``check()`` (sync or async) is truthy; return it, or fail after ``within`` s.

    Tests wait for outcomes this way instead of sleeping a fixed time: fast on an idle
    machine, still correct on a loaded one.
    """
    import asyncio

    deadline = time.monotonic() + within
    while True:
        value = check()
        if isinstance(value, Awaitable):
            value = await value
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {within} s waiting for {what or check}")
        await asyncio.sleep(interval)


class ClockPlayer:
    """Plays the sim's clock for a test: publishes ``stamp`` every ``tick_s`` of wall time.

    ``rate`` (sim seconds per wall second) is 0 by default: sim time holds still, so the
    service under test sees exactly the stamp the test sets.
    """

    def __init__(self, session: Any, stamp: float, tick_s: float = 0.02) -> None:
        self.session = session
        self.stamp = stamp
        self.rate = 0.0
        self.tick_s = tick_s
        self._task: Any = None

    async def _run(self) -> None:
        import asyncio

        last = time.monotonic()
        while True:
            now = time.monotonic()
            self.stamp += (now - last) * self.rate
            last = now
            publish_clock(self.session, self.stamp, rate=0.0)
            await asyncio.sleep(self.tick_s)

    def start(self) -> None:
        import asyncio

        self._task = asyncio.create_task(self._run())

    async def stop(self) -> None:
        import asyncio

        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task

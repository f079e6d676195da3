"""Run a set of service processes, restart the ones that crash, stop them all cleanly.

Children run in their own session (so a Ctrl-C in the terminal reaches only the launcher,
which then stops them in order) and with ``PNAV_PARENT_PID`` set (so they die with the
launcher even if it is killed). Their output goes, line by line, to a log file per service
and, if asked, to our stderr prefixed with the service's name. A host process running several
services (pnav.run.host, ``ProcessSpec.parts``) is one child, but its lines go to each service's
file by the service a line names (common.log), the host's own lines to the host's file.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import signal
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING

if TYPE_CHECKING:
    from pnav.run.prestart import Prestart

log = logging.getLogger("pnav.supervisor")

_BACKOFF_FIRST_S = 0.5
_BACKOFF_MAX_S = 5.0
_HEALTHY_AFTER_S = 10.0  # a child that ran this long resets its backoff


@dataclass
class ProcessSpec:
    name: str
    argv: list[str]
    env: dict[str, str] = field(default_factory=dict)
    # the services a host process runs (pnav.run.host): their lines go to their own log files
    parts: tuple[str, ...] = ()


@dataclass
class Child:
    spec: ProcessSpec
    process: asyncio.subprocess.Process | None = None
    started: float = 0.0
    restarts: int = 0
    backoff: float = _BACKOFF_FIRST_S
    pump: asyncio.Task[None] | None = None
    last_exit: int | None = None  # the exit code of its last run, None before any


class Supervisor:
    def __init__(
        self,
        specs: list[ProcessSpec],
        log_dir: Path,
        *,
        echo: bool = False,
        prestarted: Prestart | None = None,
    ) -> None:
        self.children = {spec.name: Child(spec) for spec in specs}
        # processes started ahead (pnav.run.prestart), taken by the first start of each child
        self.prestarted = prestarted
        self.log_dir = log_dir
        self.echo = echo
        self._stopping = False
        self._logs: dict[str, IO[str]] = {}
        # called after a child exits and after it is started again (pnav/run/supervisor_report.py)
        self.on_change: list[Callable[[], None]] = []

    def status(self) -> dict[str, dict[str, int | bool | None]]:
        """Per process: ``restarts``, ``running``, ``pid`` (None when not running) and
        ``last_exit`` (the code its last run ended with, None before any)."""
        return {
            name: {
                "restarts": child.restarts,
                "running": _alive(child),
                "pid": child.process.pid if child.process is not None and _alive(child) else None,
                "last_exit": child.last_exit,
            }
            for name, child in self.children.items()
        }

    def _changed(self) -> None:
        for listener in self.on_change:
            try:
                listener()
            except Exception:
                log.warning("a supervisor listener failed", exc_info=True)

    async def start(self) -> None:
        self.log_dir.mkdir(parents=True, exist_ok=True)
        for child in self.children.values():
            await self._spawn(child)

    async def _spawn(self, child: Child) -> None:
        env = {**os.environ, **child.spec.env, "PNAV_PARENT_PID": str(os.getpid())}
        env.setdefault("PNAV_INSTANCE", f"{child.spec.name}-1")
        warm = None
        if self.prestarted is not None:
            warm = self.prestarted.take(child.spec.name, child.spec.argv, env)
        if warm is not None:
            child.process = warm.process
        else:
            child.process = await asyncio.create_subprocess_exec(
                *child.spec.argv,
                env=env,
                stdout=asyncio.subprocess.PIPE,
                stderr=asyncio.subprocess.STDOUT,
                start_new_session=True,
            )
        child.started = time.monotonic()
        child.pump = asyncio.create_task(self._pump(child, child.process), name=child.spec.name)

    def _log(self, name: str) -> IO[str]:
        if name not in self._logs:
            self._logs[name] = (self.log_dir / f"{name}.log").open("a", buffering=1)
        return self._logs[name]

    async def _pump(self, child: Child, process: asyncio.subprocess.Process) -> None:
        name = writer = child.spec.name
        parts = child.spec.parts
        assert process.stdout is not None
        async for raw in process.stdout:
            line = raw.decode(errors="replace").rstrip("\n")
            if parts:
                writer = line_writer(line, parts, name, writer)
            self._log(writer).write(line + "\n")
            if self.echo:
                print(f"{writer:>10} | {line}", file=sys.stderr, flush=True)

    def pids(self) -> dict[str, int]:
        return {
            name: child.process.pid
            for name, child in self.children.items()
            if child.process is not None and child.process.returncode is None
        }

    async def watch(self, stop: asyncio.Event) -> None:
        """Restart children that exit until ``stop`` is set."""
        while not stop.is_set():
            waits = {
                asyncio.ensure_future(child.process.wait()): child
                for child in self.children.values()
                if child.process is not None
            }
            stopper = asyncio.ensure_future(stop.wait())
            done, pending = await asyncio.wait(
                {*waits, stopper}, return_when=asyncio.FIRST_COMPLETED
            )
            for task in pending:
                task.cancel()
            if stop.is_set():
                return
            for task in done:
                child = waits.get(task)
                if child is not None:
                    await self._restart(child, task.result())

    async def _restart(self, child: Child, code: int) -> None:
        if child.pump is not None:
            await child.pump
        ran_for = time.monotonic() - child.started
        if ran_for > _HEALTHY_AFTER_S:
            child.backoff = _BACKOFF_FIRST_S
        child.restarts += 1
        child.last_exit = code
        self._changed()
        log.warning(
            "%s exited with code %s after %.1f s; restarting in %.1f s (restart %d)",
            child.spec.name,
            code,
            ran_for,
            child.backoff,
            child.restarts,
        )
        await asyncio.sleep(child.backoff)
        child.backoff = min(child.backoff * 2, _BACKOFF_MAX_S)
        if not self._stopping:
            await self._spawn(child)
            self._changed()

    async def stop(self, grace_s: float = 8.0) -> None:
        """SIGTERM every child (last started first), wait ``grace_s``, SIGKILL the rest."""
        self._stopping = True
        live = [c for c in reversed(self.children.values()) if _alive(c)]
        for child in live:
            assert child.process is not None
            with contextlib.suppress(ProcessLookupError):
                child.process.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + grace_s
        for child in live:
            assert child.process is not None
            try:
                await asyncio.wait_for(child.process.wait(), max(0.1, deadline - time.monotonic()))
            except TimeoutError:
                log.warning("%s did not stop in %.0f s; killing it", child.spec.name, grace_s)
                with contextlib.suppress(ProcessLookupError):
                    child.process.kill()
                await child.process.wait()
        for child in self.children.values():
            if child.pump is not None:
                with contextlib.suppress(Exception):
                    await asyncio.wait_for(child.pump, 2)
        for out in self._logs.values():
            out.close()
        self._logs.clear()


def line_writer(line: str, parts: tuple[str, ...], host: str, previous: str) -> str:
    """Whose log a host's ``line`` goes to: the service it names in its third field
    (``<time> <LEVEL> <service> ...``, common.log); a line of no such form (a traceback's)
    continues the previous line's; any other, the host's."""
    fields = line.split(" ", 3)
    if len(fields) >= 3 and fields[0][:2].isdigit() and fields[0].endswith("Z"):
        return fields[2] if fields[2] in parts else host
    return previous


def _alive(child: Child) -> bool:
    return child.process is not None and child.process.returncode is None

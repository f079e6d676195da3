"""Start the whole stack on one machine: Postgres, a Zenoh router, and every service.

Used by ``pnav up`` (until Ctrl-C), ``pnav demo`` (for one mission) and the start-up
benchmark. Services are separate processes under a :class:`~pnav.supervisor.Supervisor`.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path

from common.errors import UsageError
from common.stack import LocalStack, local_stack
from pnav import stackfile
from pnav.supervisor import ProcessSpec, Supervisor

ROOT = Path(__file__).resolve().parents[1]
WORLDS = ROOT / "worlds"
SCENARIO_SERVICES = ("strategy", "planner", "controller", "decision")
DEFAULT_ZENOH_PORT = 7447


def resolve_world(world: str) -> Path:
    """A world name (``warehouse``) or a path to a world file."""
    candidates = [Path(world), WORLDS / world, WORLDS / f"{world}.yaml"]
    for path in candidates:
        if path.is_file():
            return path.resolve()
    names = ", ".join(sorted(p.stem for p in WORLDS.glob("*.yaml")))
    raise UsageError(f"no world {world!r}: give a world file, or one of: {names}")


@dataclass
class StackOptions:
    world: str = "warehouse"
    rate: str = "1"
    gui: bool = False
    robots: int | None = None
    battery: float | None = None
    data_dir: Path | None = None
    zenoh_port: int | None = DEFAULT_ZENOH_PORT  # None: any free port
    log_dir: Path | None = None
    echo: bool = False
    services: tuple[str, ...] = ("sim", "bridge", *SCENARIO_SERVICES)
    extra_env: dict[str, str] = field(default_factory=dict)


@dataclass
class RunningStack:
    local: LocalStack
    supervisor: Supervisor
    options: StackOptions
    world_path: Path
    log_dir: Path


def service_specs(local: LocalStack, options: StackOptions, world: Path) -> list[ProcessSpec]:
    env = {**local.env(), **options.extra_env}
    specs = []
    for name in options.services:
        argv = [sys.executable, "-m", f"services.{name}"]
        if name == "sim":
            argv += ["--world", str(world), "--rate", options.rate]
            if options.gui:
                argv.append("--gui")
            if options.robots is not None:
                argv += ["--robots", str(options.robots)]
            if options.battery is not None:
                argv += ["--battery", str(options.battery)]
        specs.append(ProcessSpec(name, argv, env))
    return specs


@contextlib.asynccontextmanager
async def launched(options: StackOptions) -> AsyncIterator[RunningStack]:
    world = resolve_world(options.world)
    log_dir = options.log_dir or Path(tempfile.mkdtemp(prefix="pnav-logs-"))
    async with local_stack(options.data_dir, options.zenoh_port) as local:
        supervisor = Supervisor(service_specs(local, options, world), log_dir, echo=options.echo)
        running = RunningStack(local, supervisor, options, world, log_dir)
        stackfile.write(
            stackfile.StackInfo(
                pid=os.getpid(),
                database_url=local.database_url,
                zenoh_connect=local.zenoh.connect[0],
                world=str(world),
                rate=options.rate,
                log_dir=str(log_dir),
            )
        )
        try:
            await supervisor.start()
            yield running
        finally:
            await supervisor.stop()
            stackfile.remove(os.getpid())

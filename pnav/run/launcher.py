"""Start the whole stack on one machine: Postgres, a Zenoh router, and every service.

Used by ``pnav up`` (until Ctrl-C), ``pnav demo`` (for one mission) and the benchmarks, with
the options of pnav/run/stack_options.py.
Services run under a :class:`~pnav.run.process_supervisor.Supervisor`, each in a process of its own
(``processes="separate"``) or, composed, the scenario services together in one host process
(pnav.run.host; ``"composed"``, and ``"auto"`` on a machine of at most
:data:`COMPOSE_AT_MOST_CORES` cores). A replicated or replaced service always runs apart.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import os
import shlex
import socket
import sys
import tempfile
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import cast

from zenoh import Session

from common.config import ZenohSettings
from common.contract import acl
from common.errors import UsageError
from pnav.run import stackfile
from pnav.run.composition import HOST_PROCESS, host_spec, hosted, resolve_processes
from pnav.run.embedded_postgres import free_port
from pnav.run.local_stack import LocalStack, local_stack
from pnav.run.prestart import Prestart
from pnav.run.process_supervisor import ProcessSpec, Supervisor
from pnav.run.stack_options import SCENARIO_SERVICES, DashboardOptions, StackOptions
from pnav.run.supervisor_report import SupervisorReport

ROOT = Path(__file__).resolve().parents[2]
WORLDS = ROOT / "worlds"


def resolve_world(world: str) -> Path:
    """A world name (``warehouse``) or a path to a world file."""
    candidates = [Path(world), WORLDS / world, WORLDS / f"{world}.yaml"]
    for path in candidates:
        if path.is_file():
            return path.resolve()
    names = ", ".join(sorted(p.stem for p in WORLDS.glob("*.yaml")))
    raise UsageError(f"no world {world!r}: give a world file, or one of: {names}")


def check_world(world: Path, model: str | None) -> None:
    """Load the world as the sim will, with its robots' models: a bad world or model is a
    one-line UsageError now, not a sim that exits and is restarted over and over."""
    from services.sim.world_spec import load_world

    load_world(world, model)


@dataclass
class RunningStack:
    local: LocalStack
    supervisor: Supervisor
    options: StackOptions
    world_path: Path
    log_dir: Path

    @property
    def dashboard_url(self) -> str | None:
        dashboard = self.options.dashboard
        return None if dashboard is None else dashboard.url

    def process_of(self, service: str) -> str:
        """The name of the supervised process running ``service`` (the host's when it is
        composed)."""
        return HOST_PROCESS if service in hosted(self.options) else service


MAX_REPLICAS = 32


def parse_replicas(values: list[str] | tuple[str, ...] | None) -> dict[str, int]:
    """``["controller=3", "planner=2,decision=2"]`` -> ``{"controller": 3, ...}``; a bare
    ``"3"`` asks for 3 of every scenario service.

    Only scenario services scale: two sims would be two worlds with the same robot ids, two
    bridges would store every sensor message twice. A later value for a service wins.
    """
    out: dict[str, int] = {}
    for value in values or ():
        for item in value.split(","):
            item = item.strip()
            if not item:
                continue
            name, sep, count = item.partition("=")
            name = name.strip()
            if not sep and name.isdigit():
                for service in SCENARIO_SERVICES:
                    out.update(parse_replicas([f"{service}={name}"]))
                continue
            if not sep:
                raise UsageError(f"--replicas {item!r}: write SERVICE=N, e.g. controller=3")
            if name not in SCENARIO_SERVICES:
                raise UsageError(
                    f"--replicas {item!r}: only the scenario services scale "
                    f"({', '.join(SCENARIO_SERVICES)})"
                )
            try:
                n = int(count)
            except ValueError:
                raise UsageError(f"--replicas {item!r}: {count!r} is not a whole number") from None
            if not 1 <= n <= MAX_REPLICAS:
                raise UsageError(f"--replicas {item!r}: between 1 and {MAX_REPLICAS} replicas")
            out[name] = n
    return out


def parse_replace(values: list[str] | tuple[str, ...] | None) -> dict[str, list[str]]:
    """``["controller=python -m examples.sql_controller"]`` -> ``{"controller": [...]}``.

    Only a scenario service can be swapped: the sim and the bridge are the robot's side, not
    a part of the navigation design one would compare. ``python`` is this interpreter, so a
    module of this checkout runs with the same packages.
    """
    out: dict[str, list[str]] = {}
    for value in values or ():
        name, sep, command = value.partition("=")
        name = name.strip()
        if not sep or not command.strip():
            raise UsageError(f"--replace {value!r}: write SERVICE=COMMAND")
        if name not in SCENARIO_SERVICES:
            raise UsageError(
                f"--replace {value!r}: only a scenario service can be replaced "
                f"({', '.join(SCENARIO_SERVICES)})"
            )
        try:
            argv = shlex.split(command)
        except ValueError as exc:
            raise UsageError(f"--replace {value!r}: {exc}") from None
        if argv[0] in ("python", "python3"):
            argv[0] = sys.executable
        out[name] = argv
    return out


def lockstep_env(options: StackOptions) -> dict[str, str]:
    """PNAV_LOCKSTEP for a stack run in lockstep (docs/SIM.md): every service it starts but
    the sim (which waits for them) and those replaced by another command (which may not
    take part: the sim would hold for them)."""
    names = [s for s in options.services if s != "sim" and s not in options.replace]
    return {"PNAV_LOCKSTEP": ",".join(names)}


def record_target(path: Path) -> Path:
    """The MCAP file ``--record`` names, checked before anything starts: a recording is never
    overwritten, and its folder must exist."""
    path = path.expanduser()
    if path.exists():
        raise UsageError(f"--record {path}: the file exists; remove it or choose another name")
    if not path.parent.is_dir():
        raise UsageError(f"--record {path}: no folder {path.parent}")
    return path.resolve()


def recorder_spec(local: LocalStack, options: StackOptions) -> list[ProcessSpec]:
    """The recorder process when ``options.record`` names a file. It comes first: the
    supervisor stops the last started first, so the recorder stops after every service and
    the file holds the mission to its end."""
    if options.record is None:
        return []
    argv = [sys.executable, "-m", "pnav.record", str(options.record)]
    argv += ["--encoding", options.record_encoding]
    env = {**local.env(), "PNAV_DATABASE_URL": local.url_for("user"), **options.extra_env}
    return [ProcessSpec("recorder", argv, env)]


def sim_options(options: StackOptions, world: Path) -> list[str]:
    """The sim's command-line options."""
    argv = ["--world", str(world), "--rate", options.rate]
    if options.gui:
        argv.append("--gui")
    if options.robots is not None:
        argv += ["--robots", str(options.robots)]
    if options.battery is not None:
        argv += ["--battery", str(options.battery)]
    if options.model is not None:
        argv += ["--model", options.model]
    if options.sim_held:
        argv.append("--held")
    return argv


def service_specs(local: LocalStack, options: StackOptions, world: Path) -> list[ProcessSpec]:
    """One process per service; ``options.replicas[name]`` processes for a replicated one,
    named ``name-1``, ``name-2``... with ``PNAV_INSTANCE`` set to that name (a lone process
    keeps the plain name, and the supervisor gives it instance ``name-1``). Composed, the
    hosted services are one host process, started where the first of them would be."""
    specs = []
    in_host = hosted(options)
    for name in options.services:
        if name in in_host:
            if name == in_host[0]:
                specs.append(host_spec(local, options, in_host))
            continue
        env = {
            **local.env(),
            **local.zenoh_for(name).to_env(),  # a replacement acts as the service it replaces
            **service_database(local, name),
            **options.extra_env,
        }
        argv = options.replace.get(name) or [sys.executable, "-m", f"services.{name}"]
        if name == "sim":
            argv += sim_options(options, world)
        replicas = options.replicas.get(name, 1)
        if replicas > 1 and name not in SCENARIO_SERVICES:
            raise UsageError(f"{name} cannot be replicated: only {', '.join(SCENARIO_SERVICES)}")
        if replicas <= 1:
            specs.append(ProcessSpec(name, argv, env))
            continue
        for i in range(1, replicas + 1):
            instance = f"{name}-{i}"
            specs.append(ProcessSpec(instance, argv, {**env, "PNAV_INSTANCE": instance}))
    if options.dashboard is not None:
        # the page writes only people's rows: it acts as people do (pnav_user)
        people = {**local.env(), "PNAV_DATABASE_URL": local.url_for("user"), **options.extra_env}
        specs.append(dashboard_spec(people, options.dashboard))
    if options.extra_env.get("PNAV_ROBOT_LINK") == "ros2" and "bridge" in options.services:
        # RViz's goals are people's rows: written as pnav_user (pnav/ros2), not by the bridge
        people = {**local.env(), "PNAV_DATABASE_URL": local.url_for("user"), **options.extra_env}
        specs.append(ProcessSpec("rviz", [sys.executable, "-m", "pnav.ros2"], people))
    return specs


def dashboard_spec(env: dict[str, str], dashboard: DashboardOptions) -> ProcessSpec:
    """The dashboard's process: a service like the others, with its address. It takes no
    part in lockstep (it writes only what people ask for)."""
    if dashboard.port is None:
        raise UsageError("the dashboard's port is chosen by the launcher (resolve_dashboard)")
    address = {"PNAV_DASHBOARD_HOST": dashboard.host, "PNAV_DASHBOARD_PORT": str(dashboard.port)}
    if dashboard.allowed_hosts:
        address["PNAV_DASHBOARD_ALLOWED_HOSTS"] = ",".join(dashboard.allowed_hosts)
    argv = [sys.executable, "-m", "services.dashboard"]
    return ProcessSpec("dashboard", argv, {**env, **address})


def resolve_dashboard(options: StackOptions) -> StackOptions:
    """``options`` with the dashboard's port chosen (a free one when None) and checked free
    now, so a port in use is one clear error instead of a dashboard restarted forever."""
    dashboard = options.dashboard
    if dashboard is None:
        return options
    port = dashboard.port if dashboard.port is not None else free_port()
    try:
        infos = socket.getaddrinfo(dashboard.host, port, type=socket.SOCK_STREAM)
        with socket.socket(infos[0][0], socket.SOCK_STREAM) as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            probe.bind(infos[0][4])
    except OSError as exc:
        raise UsageError(
            f"the dashboard cannot listen on {dashboard.host}:{port} ({exc.strerror or exc}): "
            "pick another with --http-port, or run without it (--no-dashboard)"
        ) from None
    return dataclasses.replace(options, dashboard=dataclasses.replace(dashboard, port=port))


def service_database(local: LocalStack, name: str) -> dict[str, str]:
    """PNAV_DATABASE_URL of service ``name``: its own role's (a replacement, docs/SWAP.md,
    gets the role of the service it replaces); none for the sim, which has no database."""
    if name == "sim":
        return {"PNAV_DATABASE_URL": ""}
    return {"PNAV_DATABASE_URL": local.url_for(name)}


def planned(options: StackOptions, world: Path) -> list[tuple[str, list[str]]]:
    """The name and command of every process the stack will run, before the stack exists
    (their commands do not depend on it, only their environments do)."""
    stand_in = LocalStack("", ZenohSettings(), cast(Session, None), None)
    specs = recorder_spec(stand_in, options) + service_specs(stand_in, options, world)
    return [(spec.name, spec.argv) for spec in specs]


def _ros_domains(env: dict[str, str]) -> tuple[int, ...]:
    """The ROS 2 domain the stack's own router carries: a ROS 2 robot link with no rmw_zenoh
    router of its own (``--ros-router``) speaks ROS 2 through it."""
    if env.get("PNAV_ROBOT_LINK") != "ros2" or env.get("PNAV_ROS2_CONNECT"):
        return ()
    return (int(env.get("PNAV_ROS_DOMAIN_ID") or 0),)


@contextlib.asynccontextmanager
async def launched(options: StackOptions) -> AsyncIterator[RunningStack]:
    world = resolve_world(options.world)
    options = resolve_dashboard(options)
    options = dataclasses.replace(options, processes=resolve_processes(options.processes))
    # the services import their code while the world is checked and Postgres gets ready
    # (pnav.run.prestart)
    prestart = Prestart()
    try:
        await prestart.start(planned(options, world))
        if "sim" in options.services and "sim" not in options.replace:
            check_world(world, options.model)
        log_dir = options.log_dir or Path(tempfile.mkdtemp(prefix="pnav-logs-"))
        ros_domains = _ros_domains(options.extra_env)
        in_host = hosted(options)
        hosts = (acl.host_identity(in_host),) if in_host else ()
        async with _stack(options, log_dir, world, ros_domains, hosts, prestart) as running:
            yield running
    finally:
        await prestart.close()


@contextlib.asynccontextmanager
async def _stack(
    options: StackOptions,
    log_dir: Path,
    world: Path,
    ros_domains: tuple[int, ...],
    hosts: tuple[str, ...],
    prestart: Prestart,
) -> AsyncIterator[RunningStack]:
    async with local_stack(
        options.data_dir,
        options.zenoh_port,
        bus=options.bus,
        ros_domains=ros_domains,
        hosts=(*acl.DEFAULT_HOSTS, *hosts),
    ) as local:
        specs = recorder_spec(local, options) + service_specs(local, options, world)
        supervisor = Supervisor(specs, log_dir, echo=options.echo, prestarted=prestart)
        running = RunningStack(local, supervisor, options, world, log_dir)
        stackfile.write(
            stackfile.StackInfo(
                pid=os.getpid(),
                database_url=local.url_for("user"),  # the CLI acts for people
                zenoh_connect=local.zenoh.connect[0],
                world=str(world),
                rate=options.rate,
                log_dir=str(log_dir),
                postgres_dir=str(local.postgres.data_dir) if local.postgres else "",
                postgres_temporary=local.postgres is not None and local.postgres.temporary,
                role_urls=dict(local.role_urls),
                zenoh_passwords=dict(local.bus.passwords) if local.bus else {},
            )
        )
        # Supervision runs for as long as the stack does: a crashed service is restarted
        # whether the stack serves `pnav up`, the demo or a test.
        stop_watching = asyncio.Event()
        watcher: asyncio.Task[None] | None = None
        report = SupervisorReport(supervisor, local.router)  # restarts, for /metrics
        try:
            await supervisor.start()
            await prestart.close()  # any not taken: a process the stack no longer runs
            report.start()
            watcher = asyncio.create_task(supervisor.watch(stop_watching), name="supervise")
            yield running
        finally:
            await report.close()
            stop_watching.set()
            if watcher is not None:
                try:
                    await asyncio.wait_for(watcher, 10)  # a restart under way finishes first
                except TimeoutError:
                    pass
            await supervisor.stop()
            stackfile.remove(os.getpid())

"""How a local stack's services share processes: one each, or composed in a host process.

``--processes separate`` runs every service in a process of its own. ``composed`` runs
strategy, planner, controller and decision in one host process (pnav.run.host: one interpreter,
one event loop, one Zenoh session; each service keeps its package, engine, store, Postgres
role and pool, lease and logs). ``auto`` (the default) composes on a machine of at most
:data:`COMPOSE_AT_MOST_CORES` cores. A replicated or replaced service always runs apart.
"""

from __future__ import annotations

import os
import sys
from typing import TYPE_CHECKING

from common.contract import acl
from common.errors import UsageError
from pnav.run.process_supervisor import ProcessSpec

if TYPE_CHECKING:
    from pnav.run.local_stack import LocalStack
    from pnav.run.stack_options import StackOptions

# --processes: auto (composed on a machine of few cores), composed, separate
PROCESSES = ("auto", "composed", "separate")
# On this many cores or fewer "auto" composes: four interpreters' wake-ups and the router
# hops between them cost more there than one loop's serialisation (docs/BENCHMARKS.md,
# "Composition"); with more cores, separate processes run the services in parallel.
COMPOSE_AT_MOST_CORES = 4
HOST_PROCESS = "host"


def parse_processes(value: str) -> str:
    """``--processes``: one of :data:`PROCESSES`."""
    choice = value.strip().lower()
    if choice not in PROCESSES:
        raise UsageError(f"--processes {value!r}: one of {', '.join(PROCESSES)}")
    return choice


def resolve_processes(value: str, cores: int | None = None) -> str:
    """``composed`` or ``separate``; ``auto`` composes on at most COMPOSE_AT_MOST_CORES
    cores (``cores``: os.cpu_count() unless given)."""
    value = parse_processes(value)
    if value != "auto":
        return value
    cores = os.cpu_count() if cores is None else cores
    return "composed" if (cores or 1) <= COMPOSE_AT_MOST_CORES else "separate"


def hosted(options: StackOptions) -> tuple[str, ...]:
    """The services the host process runs: none when separate, or when fewer than two are
    left once the replicated and replaced ones (which run apart) are taken out."""
    if resolve_processes(options.processes) != "composed":
        return ()
    names = tuple(
        name
        for name in options.services
        if name in options.host_services
        and name not in options.replace
        and options.replicas.get(name, 1) <= 1
    )
    return names if len(names) >= 2 else ()


def host_spec(local: LocalStack, options: StackOptions, services: tuple[str, ...]) -> ProcessSpec:
    """The host process of ``services`` (pnav.run.host): its identity on the bus is theirs
    together (acl.host_identity), each service keeps its own Postgres role."""
    identity = acl.host_identity(services)
    if local.bus is not None and identity not in local.bus.passwords:
        raise UsageError(f"the stack's router does not know the host identity {identity}")
    env = {**local.env(), **local.zenoh_for(identity).to_env(), "PNAV_DATABASE_URL": ""}
    for name in services:
        env[f"PNAV_DATABASE_URL_{name.upper()}"] = local.url_for(name)  # its own role
    env.update(options.extra_env)
    argv = [sys.executable, "-m", "pnav.run.host", *services]
    # each service's lines go to its own log file, as from a process of its own
    return ProcessSpec(HOST_PROCESS, argv, env, parts=services)

"""``python -m pnav.run.host strategy planner controller decision``: several services, one process.

A host runs the services it is given in one interpreter, on one uvloop event loop, over one
Zenoh session (Nav2's component container is the model). Each service is what it is in a
process of its own: its package, engine, store, Postgres role and pool, robot leases,
liveliness token and instance, and its log lines name it (common.log.speak_as). The services
still share no code and do not import each other: the host finds each one's entry by name
in the ``pnav.services`` entry points (pyproject.toml) and calls it with its own
configuration and the host's session. A notification one hosted service puts reaches the
others' subscribers inside the session, without a trip through the router.

Environment: what a service process reads (PNAV_ZENOH_* are the host's own: its identity
is common.contract.acl.host_identity of its services), and per service
``PNAV_DATABASE_URL_<SERVICE>`` (its role's DSN; PNAV_DATABASE_URL when unset) and
``PNAV_INSTANCE_<SERVICE>`` (default ``<service>-1``, as a lone process of it).

The trade-off: a service that fails ends the host, with a line naming the service, and the
supervisor restarts the host, so its co-hosted services restart with it. Exit codes as a
service's: 0 stopped, 1 a service failed, 2 misconfigured.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import sys
from collections.abc import Mapping
from importlib.metadata import entry_points

import zenoh

from common import bus, log
from common.config import ServiceConfig, ZenohSettings
from common.errors import ConfigError, UsageError
from common.lifeline import die_with_parent
from common.outage import fold_outage_logs
from common.runtime import HostedMain, run_stoppable

logger = logging.getLogger("pnav.host")
GROUP = "pnav.services"
HOST = "host"


def hostable() -> tuple[str, ...]:
    """The services a host can run: the names in the ``pnav.services`` entry points."""
    return tuple(sorted(p.name for p in entry_points(group=GROUP)))


def entry(service: str) -> HostedMain:
    """``service``'s hosted entry, ``serve(config, stop, session)``."""
    points = [p for p in entry_points(group=GROUP) if p.name == service]
    if not points:
        names = ", ".join(hostable()) or "none: is the package installed (scripts/setup)?"
        raise UsageError(f"no service {service!r} to host: the {GROUP} entry points are {names}")
    loaded: HostedMain = points[0].load()
    return loaded


def service_env(service: str, env: Mapping[str, str]) -> dict[str, str]:
    """The environment ``service`` would have in a process of its own."""
    upper = service.upper()
    out = dict(env)
    out["PNAV_DATABASE_URL"] = env.get(f"PNAV_DATABASE_URL_{upper}") or env.get(
        "PNAV_DATABASE_URL", ""
    )
    out["PNAV_INSTANCE"] = env.get(f"PNAV_INSTANCE_{upper}") or f"{service}-1"
    return out


def configs(services: list[str], env: Mapping[str, str]) -> dict[str, ServiceConfig]:
    if not services:
        raise UsageError("name the services to host, e.g. strategy planner controller decision")
    if len(set(services)) != len(services):
        raise UsageError(f"a service is named twice: {' '.join(services)}")
    out = {}
    for name in services:
        try:
            out[name] = ServiceConfig.from_env(name, service_env(name, env))
        except ConfigError as exc:
            raise UsageError(f"{name}: {exc}") from None
    return out


def prestart(services: list[str]) -> None:
    """Import the services' code ahead of the environment (pnav.run.prestart): the entries a
    host started this way finds already loaded."""
    for name in services:
        entry(name)


class ServiceFailed(Exception):
    """A hosted service raised, or ended while nobody asked it to stop."""

    def __init__(self, service: str) -> None:
        super().__init__(service)
        self.service = service


async def _run_one(
    name: str, main: HostedMain, config: ServiceConfig, stop: asyncio.Event, session: zenoh.Session
) -> None:
    log.speak_as(name)  # this task's lines, and its tasks', name the service
    try:
        await main(config, stop, session)
    except Exception:
        logger.exception("service failed: the host stops", extra={"service": name})
        raise ServiceFailed(name) from None
    if not stop.is_set():
        logger.error("service ended on its own: the host stops", extra={"service": name})
        raise ServiceFailed(name)
    log.event(logger, logging.INFO, "stopped", service=name)


async def host(
    services: list[str], stop: asyncio.Event, env: Mapping[str, str] | None = None
) -> str | None:
    """Run ``services`` until ``stop`` is set or one fails; the failed one's name, or None."""
    env = os.environ if env is None else env
    settings = configs(services, env)
    mains = {name: entry(name) for name in services}
    session = await asyncio.to_thread(bus.open_session, ZenohSettings.from_env(env))
    log.event(logger, logging.INFO, "host up", services=",".join(services))
    failed: str | None = None
    try:
        tasks = {
            asyncio.create_task(
                _run_one(name, mains[name], settings[name], stop, session), name=name
            ): name
            for name in services
        }
        pending = set(tasks)
        while pending:
            done, pending = await asyncio.wait(pending, return_when=asyncio.FIRST_EXCEPTION)
            for task in done:
                if task.exception() is not None and failed is None:
                    failed = tasks[task]
                    stop.set()  # the others drain and stop as on SIGTERM
    finally:
        await asyncio.to_thread(session.close)
    return failed


def main(argv: list[str] | None = None) -> int:
    services = list(sys.argv[1:] if argv is None else argv)
    die_with_parent()
    log.setup(HOST, os.environ.get("PNAV_LOG_LEVEL"))
    fold_outage_logs()

    code, failed = run_stoppable(lambda stop: host(services, stop))
    if code:
        return code
    if failed is not None:
        log.event(logger, logging.ERROR, "host stopped: a service failed", service=failed)
        return 1
    log.event(logger, logging.INFO, "host stopped", services=",".join(services))
    return 0


if __name__ == "__main__":
    with contextlib.suppress(KeyboardInterrupt):
        sys.exit(main())

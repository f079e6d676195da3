"""What a local stack is asked to run: the world, the services and how they share processes,
the dashboard. Read by the launcher (pnav/run/launcher.py) and by how the services are
composed (pnav/run/composition.py); written by ``pnav up``, ``pnav demo`` and the benchmarks.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from common.contract import acl
from pnav.run.local_stack import BusCredentials

SCENARIO_SERVICES = ("strategy", "planner", "controller", "decision")
DEFAULT_ZENOH_PORT = 7447
DEFAULT_HTTP_PORT = 8080


@dataclass(frozen=True)
class DashboardOptions:
    """The dashboard the stack serves (services/dashboard, docs/DASHBOARD.md)."""

    host: str = "127.0.0.1"
    port: int | None = DEFAULT_HTTP_PORT  # None: a free port, chosen at launch
    # host names the page may be reached by besides the loopback ones and ``host``
    # (PNAV_DASHBOARD_ALLOWED_HOSTS, services/dashboard/gate.py)
    allowed_hosts: tuple[str, ...] = ()

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"


@dataclass
class StackOptions:
    world: str = "warehouse"
    rate: str = "1"
    gui: bool = False
    robots: int | None = None
    battery: float | None = None
    # the sim holds at sim time 0 and runs only as far as pnav/sim/run lets it (--held,
    # services/sim/hold.py): ``pnav demo`` steps its mission on sim time so
    sim_held: bool = False
    # robot model of every robot the world does not give one (None: the Burger)
    model: str | None = None
    data_dir: Path | None = None
    zenoh_port: int | None = DEFAULT_ZENOH_PORT  # None: any free port
    log_dir: Path | None = None
    echo: bool = False
    services: tuple[str, ...] = ("sim", "bridge", *SCENARIO_SERVICES)
    extra_env: dict[str, str] = field(default_factory=dict)
    # the Zenoh users of the run (made for it if None); given when extra_env points the
    # stack at a router of the caller's that checks the same users (pnav bench faults)
    bus: BusCredentials | None = None
    # processes per scenario service (default 1): replicas split the robots (common.lease)
    replicas: dict[str, int] = field(default_factory=dict)
    # service -> the command run in its place (another implementation, docs/SWAP.md)
    replace: dict[str, list[str]] = field(default_factory=dict)
    # record the mission into this MCAP file (pnav/record, docs/RECORDING.md)
    record: Path | None = None
    # its encoding: "foxglove" (Foxglove's schemas) or "ros2" (ros2msg, CDR)
    record_encoding: str = "foxglove"
    # the dashboard, supervised like the services; None: none (tests and benchmarks)
    dashboard: DashboardOptions | None = None
    # one process per service ("separate"), the scenario services in one host process
    # ("composed"), or composed on a machine of few cores ("auto": resolve_processes)
    processes: str = field(default_factory=lambda: os.environ.get("PNAV_PROCESSES") or "auto")
    # the services a composed stack runs in its host (those not replicated nor replaced)
    host_services: tuple[str, ...] = acl.DEFAULT_HOSTED

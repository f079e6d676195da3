"""The options that say where the dashboard is served: ``pnav up`` and ``pnav demo``
(docs/DASHBOARD.md)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    # imported when used: `pnav --help` does not load the launcher's dependencies
    from pnav.run.stack_options import DashboardOptions


def _port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 1 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"must be a port number from 1 to 65535, got {text!r}")
    return value


def _host_name(text: str) -> str:
    """A host name as PNAV_DASHBOARD_ALLOWED_HOSTS takes it (checked by the dashboard's own
    settings, so both refuse the same)."""
    from common.errors import ConfigError
    from services.dashboard.settings import DashboardSettings

    name = text.strip().lower()
    try:
        DashboardSettings(allowed_hosts=(name,))
    except ConfigError:
        raise argparse.ArgumentTypeError(
            f"must be a host name or address (no scheme, port or path), got {text!r}"
        ) from None
    return name


def add_dashboard_options(parser: argparse.ArgumentParser, default_port: int | None) -> None:
    """--http-port, --http-host and --no-dashboard; ``default_port`` None: a free port."""
    where = "a free port, printed" if default_port is None else str(default_port)
    parser.add_argument(
        "--http-port", type=_port, default=default_port, help=f"dashboard port ({where})"
    )
    parser.add_argument(
        "--http-host",
        default="127.0.0.1",
        help="dashboard address (127.0.0.1: this machine only; 0.0.0.0 serves a page that "
        "sends robots, with no login, to the whole network)",
    )
    parser.add_argument(
        "--http-allow-host",
        action="append",
        type=_host_name,
        default=[],
        metavar="NAME",
        help="a host name the page may also be reached by (besides 127.0.0.1, localhost, "
        "[::1] and --http-host); any other name is refused, as DNS rebinding would use one",
    )
    parser.add_argument("--no-dashboard", action="store_true", help="serve no dashboard")


def dashboard_options(args: argparse.Namespace) -> DashboardOptions | None:
    from pnav.run.stack_options import DashboardOptions

    if args.no_dashboard:
        return None
    allowed = tuple(args.http_allow_host)
    return DashboardOptions(host=args.http_host, port=args.http_port, allowed_hosts=allowed)

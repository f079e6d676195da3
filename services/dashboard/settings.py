"""The dashboard's own settings, from ``PNAV_DASHBOARD_*`` (the connections are the usual
``PNAV_DATABASE_URL`` and ``PNAV_ZENOH_*``, common.config)."""

from __future__ import annotations

import ipaddress
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field

from common.errors import ConfigError

Env = Mapping[str, str]

# a DNS name or an IPv4 address, or an IPv6 address in brackets or not
_HOST_NAME = re.compile(r"^(?:[a-z0-9_]([a-z0-9_.-]*[a-z0-9_.])?|\[?[0-9a-f:.]+\]?)$")


@dataclass(frozen=True)
class DashboardSettings:
    """Where the page is served and how often it is updated.

    ``host`` is 127.0.0.1 unless asked otherwise: the page writes goals and strategies, and
    has no login, so it is reachable from this machine only by default (a container sets
    0.0.0.0 and publishes the port on the host's loopback).
    """

    host: str = "127.0.0.1"
    port: int = 8080
    # how often changed robots are pushed to the browsers (wall s): 10 Hz is smooth to the
    # eye and bounded whatever the sensor rates are
    push_period_s: float = 0.1
    # every table is read again this often (wall s), so a lost notification only delays
    refresh_period_s: float = 5.0
    # host names the page may be loaded from besides 127.0.0.1, localhost, [::1] and
    # ``host`` (services.dashboard.gate): the names a deployment reaches it by
    allowed_hosts: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        try:
            ipaddress.ip_address(self.host)
        except ValueError:
            if not self.host or any(c.isspace() for c in self.host):
                raise ConfigError(
                    f"PNAV_DASHBOARD_HOST={self.host!r} is not an address or host name"
                ) from None
        if not 0 <= self.port <= 65535:
            raise ConfigError(f"PNAV_DASHBOARD_PORT={self.port} must be from 0 to 65535")
        if not self.push_period_s > 0 or not self.refresh_period_s > 0:
            raise ConfigError("the dashboard's periods must be positive")
        for name in self.allowed_hosts:
            if not _HOST_NAME.match(name):
                raise ConfigError(
                    f"PNAV_DASHBOARD_ALLOWED_HOSTS: {name!r} is not a host name or address "
                    "(give names only, comma-separated: no scheme, port or path)"
                )

    @classmethod
    def from_env(cls, env: Env | None = None) -> DashboardSettings:
        env = os.environ if env is None else env
        host = env.get("PNAV_DASHBOARD_HOST", "").strip() or cls.host
        raw = env.get("PNAV_DASHBOARD_PORT", "").strip() or str(cls.port)
        try:
            port = int(raw)
        except ValueError:
            raise ConfigError(f"PNAV_DASHBOARD_PORT={raw!r} is not a port number") from None
        allowed = env.get("PNAV_DASHBOARD_ALLOWED_HOSTS", "")
        names = tuple(n.strip().lower() for n in allowed.split(",") if n.strip())
        return cls(host=host, port=port, allowed_hosts=names)

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"

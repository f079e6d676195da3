"""Settings from the ``PNAV_*`` environment variables every proactive-nav service reads.

The names, defaults and parsing rules are those CONTRACT.md's services share (``pnav up`` and
the compose file set them), rewritten here so the example depends on nothing but the
contract. A bad value raises :class:`ConfigError` naming the variable; ``__main__`` turns
it into exit code 2, as the shipped services do.

Read here: PNAV_DATABASE_URL (required), PNAV_DB_POOL_MAX, PNAV_DB_WAIT_S, PNAV_ZENOH_MODE,
PNAV_ZENOH_CONNECT, PNAV_ZENOH_LISTEN, PNAV_ZENOH_MULTICAST, PNAV_ZENOH_CONFIG,
PNAV_ZENOH_USER and PNAV_ZENOH_PASSWORD (the router's user/password authentication; in
compose it is the ``controller`` user), PNAV_ENGINE_PERIOD_MS (this loop's fallback period:
it has no engine, but the variable means "re-read at least this often" for every service),
PNAV_STATS_PERIOD_S, PNAV_INSTANCE, PNAV_LEASES, PNAV_LEASE_PERIOD_MS, PNAV_LEASE_TIMEOUT_S,
PNAV_LOG_LEVEL. The engine's N and P (PNAV_ENGINE_MAX_RULES, PNAV_ENGINE_PAUSE_MS) have no
meaning without an engine.
"""

from __future__ import annotations

import os
import re
import socket
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TypeVar

SERVICE = "controller"  # the family it replaces: its liveliness token and its leases say so
_ID = re.compile(r"^[A-Za-z0-9_-]+$")  # one Zenoh key chunk
N = TypeVar("N", int, float)


class ConfigError(Exception):
    """A PNAV_* variable with a value that cannot be used."""


def _text(env: Mapping[str, str], name: str, default: str) -> str:
    # An empty variable counts as unset, as in the shipped services.
    return env.get(name, "").strip() or default


def _number(env: Mapping[str, str], name: str, default: float, minimum: float) -> float:
    return _parsed(env, name, default, float, "a number", minimum)


def _whole(env: Mapping[str, str], name: str, default: int, minimum: int) -> int:
    return _parsed(env, name, default, int, "a whole number", minimum)


def _parsed(
    env: Mapping[str, str], name: str, default: N, parse: Callable[[str], N], what: str, minimum: N
) -> N:
    raw = _text(env, name, str(default))
    try:
        value = parse(raw)
    except ValueError:
        raise ConfigError(f"{name}={raw!r} is not {what}") from None
    if not value >= minimum:  # NaN too
        raise ConfigError(f"{name}={raw!r} must be at least {minimum}")
    return value


def _flag(env: Mapping[str, str], name: str, default: bool) -> bool:
    raw = _text(env, name, "true" if default else "false").lower()
    if raw in ("1", "true", "yes", "on"):
        return True
    if raw in ("0", "false", "no", "off"):
        return False
    raise ConfigError(f"{name}={raw!r} is not a boolean (true/false)")


def _endpoints(env: Mapping[str, str], name: str, default: tuple[str, ...]) -> tuple[str, ...]:
    # Unlike the other variables, a *set but empty* list means "none" (a router that only
    # listens), so only an absent variable takes the default.
    raw = env.get(name)
    if raw is None:
        return default
    return tuple(part.strip() for part in raw.split(",") if part.strip())


def default_instance() -> str:
    """``<hostname>-<pid>`` with dots made dashes: what the compose health check looks for."""
    return f"{socket.gethostname()}-{os.getpid()}".replace(".", "-")


@dataclass(frozen=True)
class Settings:
    database_url: str
    zenoh_mode: str = "client"
    zenoh_connect: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    zenoh_listen: tuple[str, ...] = ()
    zenoh_multicast: bool = False
    zenoh_config_file: str | None = None
    zenoh_user: str | None = None
    zenoh_password: str | None = None
    pool_max: int = 4
    db_wait_s: float = 10.0
    period_s: float = 0.05
    stats_period_s: float = 2.0
    instance: str = ""
    leases: bool = True
    lease_period_s: float = 0.5
    lease_timeout_s: float = 5.0
    log_level: str = "INFO"

    @classmethod
    def from_env(cls, env: Mapping[str, str] | None = None) -> Settings:
        env = os.environ if env is None else env
        url = env.get("PNAV_DATABASE_URL", "").strip()
        if not url:
            raise ConfigError("PNAV_DATABASE_URL is not set: point it at the contract database")
        mode = _text(env, "PNAV_ZENOH_MODE", "client")
        if mode not in ("client", "peer", "router"):
            raise ConfigError(f"PNAV_ZENOH_MODE={mode!r} must be client, peer or router")
        if bool(env.get("PNAV_ZENOH_USER", "").strip()) != bool(env.get("PNAV_ZENOH_PASSWORD")):
            raise ConfigError("PNAV_ZENOH_USER and PNAV_ZENOH_PASSWORD go together: set both")
        instance = _text(env, "PNAV_INSTANCE", default_instance())
        if not _ID.match(instance):
            raise ConfigError(f"PNAV_INSTANCE={instance!r} must match [A-Za-z0-9_-]+")
        period_s = _number(env, "PNAV_LEASE_PERIOD_MS", 500.0, minimum=10.0) / 1000
        timeout_s = _number(env, "PNAV_LEASE_TIMEOUT_S", 5.0, minimum=1.0)
        if timeout_s < 4 * period_s:
            # the lock connection must hear from us several times before Postgres gives up
            raise ConfigError(
                f"PNAV_LEASE_TIMEOUT_S={timeout_s} must be at least 4 lease periods "
                f"({4 * period_s} s)"
            )
        return cls(
            database_url=url,
            zenoh_mode=mode,
            zenoh_connect=_endpoints(env, "PNAV_ZENOH_CONNECT", cls.zenoh_connect),
            zenoh_listen=_endpoints(env, "PNAV_ZENOH_LISTEN", ()),
            zenoh_multicast=_flag(env, "PNAV_ZENOH_MULTICAST", False),
            zenoh_config_file=env.get("PNAV_ZENOH_CONFIG") or None,
            zenoh_user=env.get("PNAV_ZENOH_USER", "").strip() or None,
            zenoh_password=env.get("PNAV_ZENOH_PASSWORD") or None,
            pool_max=_whole(env, "PNAV_DB_POOL_MAX", 4, minimum=1),
            db_wait_s=_number(env, "PNAV_DB_WAIT_S", 10.0, minimum=0.0),
            period_s=_number(env, "PNAV_ENGINE_PERIOD_MS", 50.0, minimum=0.1) / 1000,
            stats_period_s=_number(env, "PNAV_STATS_PERIOD_S", 2.0, minimum=0.1),
            instance=instance,
            leases=_flag(env, "PNAV_LEASES", True),
            lease_period_s=period_s,
            lease_timeout_s=timeout_s,
            log_level=_text(env, "PNAV_LOG_LEVEL", "INFO").upper(),
        )

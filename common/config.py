"""Typed configuration read from ``PNAV_*`` environment variables.

Each settings class is a frozen dataclass with defaults and one ``from_env()`` that reads its
variables by name; a bad value raises :class:`~common.errors.ConfigError` naming the variable.

=========================  ====================================  ===============================
variable                   meaning                               default
=========================  ====================================  ===============================
PNAV_DATABASE_URL          Postgres DSN (postgresql://...)       none: required by services
PNAV_DB_POOL_MAX           most connections in a service's pool  4
PNAV_DB_WAIT_S             how long to retry an unreachable DB   10
PNAV_DB_LOCK_TIMEOUT_MS    a service's statement that waits this 200
                           long for a lock fails (0: waits
                           forever; CONTRACT.md, *Roles*)
PNAV_ZENOH_MODE            client, peer or router                client
PNAV_ZENOH_CONNECT         comma-separated endpoints to connect  tcp/127.0.0.1:7447
PNAV_ZENOH_LISTEN          comma-separated endpoints to listen   (none)
PNAV_ZENOH_MULTICAST       multicast scouting on (true/false)    false
PNAV_ZENOH_CONFIG          path of a Zenoh JSON5 config file,    (none)
                           applied before the variables above
PNAV_ZENOH_USER            user name this process authenticates  (none: no authentication)
                           as to the router (compose: its service)
PNAV_ZENOH_PASSWORD        that user's password                  (none)
PNAV_ZENOH_USERS_FILE      user:password lines this process      (none: accepts anyone)
                           checks whoever links to it against
                           (a local stack's router)
PNAV_ENGINE_PERIOD_MS      F: activation period and bound        50
PNAV_ENGINE_MAX_RULES      N: most rules run per activation      1000
PNAV_ENGINE_PAUSE_MS       P: least pause between activations    0
PNAV_ENGINE_RULE_BUDGET_MS a rule run longer than this is logged  50
                           (once per rule type per 10 s)
PNAV_STATS_PERIOD_S        how often engine_stats is written     2.0
PNAV_INSTANCE              this process's instance id            <hostname>-<pid>
PNAV_LEASES                replicas split the robots through     on
                           Postgres advisory locks (on/off)
PNAV_LEASE_PERIOD_MS       how often a replica revises its       500
                           robots (wall time)
PNAV_LEASE_TIMEOUT_S       Postgres ends a lock connection       5
                           silent this long, freeing its robots
PNAV_LOG_LEVEL             DEBUG, INFO, WARNING, ERROR           INFO
=========================  ====================================  ===============================
"""

from __future__ import annotations

import os
import socket
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TypeVar

from common.contract import keys
from common.errors import ConfigError

Env = Mapping[str, str]
N = TypeVar("N", int, float)
D = TypeVar("D")  # a default of another type than the number (None: unset)


def _get(env: Env, name: str, default: str) -> str:
    value = env.get(name, "").strip()
    return value or default


def _float(env: Env, name: str, default: float, *, minimum: float = 0.0) -> float:
    return _parsed(env, name, default, float, "a number", minimum)


def _int(env: Env, name: str, default: int, *, minimum: int = 0) -> int:
    return _parsed(env, name, default, int, "a whole number", minimum)


def _parsed(env: Env, name: str, default: N, parse: Callable[[str], N], what: str, minimum: N) -> N:
    return env_number(
        env,
        name,
        default,
        parse,
        what=what,
        ok=lambda value: value >= minimum,  # NaN fails it too
        must=f"must be at least {minimum}",
    )


def env_number(
    env: Env,
    name: str,
    default: D,
    parse: Callable[[str], N],
    *,
    what: str = "a number",
    ok: Callable[[N], bool] = lambda _value: True,
    must: str = "",
) -> N | D:
    """The number variable ``name`` holds (``default`` when unset or blank), read by
    ``parse``; a ConfigError naming the variable when it is not ``what`` or not ``ok``
    (the message then says ``must``). The settings here, the bridge's, the metrics' and
    the sim's options read their numbers with it, each giving only its own range."""
    raw = env.get(name, "").strip()
    if not raw:
        return default
    try:
        value = parse(raw)
    except ValueError:
        raise ConfigError(f"{name}={raw!r} is not {what}") from None
    if not ok(value):
        raise ConfigError(f"{name}={raw!r} {must}")
    return value


def _bool(env: Env, name: str, default: bool) -> bool:
    raw = _get(env, name, "true" if default else "false").lower()
    if raw in ("1", "true", "yes", "on"):
        return True
    if raw in ("0", "false", "no", "off"):
        return False
    raise ConfigError(f"{name}={raw!r} is not a boolean (true/false)")


def _list(env: Env, name: str, default: tuple[str, ...]) -> tuple[str, ...]:
    raw = env.get(name)
    if raw is None:
        return default
    return tuple(part.strip() for part in raw.split(",") if part.strip())


# Batches a Zenoh link may hold waiting for its socket at the data priority (Zenoh's own
# default: 2; its maximum: 16). A notification is an express put, one batch to itself, so with
# two a link is full as soon as its writer thread misses a turn on a busy core, and a put that
# finds it full for 1 ms (``wait_before_drop``) is dropped: 2 to 3 % of them on two busy cores
# (docs/BENCHMARKS.md, sixth round). More room drops none there and waits no longer: a link
# to a frozen peer fills as before, then drops after the same 1 ms.
DATA_QUEUE_BATCHES = 16
# Zenoh takes more in its config, then panics as a link opens (its ring holds 16): refused here
DATA_QUEUE_MAX = 16


@dataclass(frozen=True)
class ZenohSettings:
    mode: str = "client"
    connect: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    listen: tuple[str, ...] = ()
    multicast: bool = False
    config_file: str | None = None
    # user/password authentication to the router (docs/DEPLOY.md, "Zenoh access control")
    user: str | None = None
    password: str | None = field(default=None, repr=False)
    # the user/password dictionary a router or peer checks the sessions that link to it
    # against (a local stack: pnav.run.local_stack); None accepts any session
    users_file: str | None = None
    data_queue: int = DATA_QUEUE_BATCHES  # transport/link/tx/queue/size/data of every link

    def __post_init__(self) -> None:
        if self.mode not in ("client", "peer", "router"):
            raise ConfigError(f"PNAV_ZENOH_MODE={self.mode!r} must be client, peer or router")
        if not 1 <= self.data_queue <= DATA_QUEUE_MAX:
            raise ConfigError(
                f"PNAV_ZENOH_DATA_QUEUE={self.data_queue} must be 1 to {DATA_QUEUE_MAX} batches"
            )
        if bool(self.user) != bool(self.password):
            raise ConfigError("PNAV_ZENOH_USER and PNAV_ZENOH_PASSWORD go together: set both")

    @classmethod
    def from_env(cls, env: Env | None = None) -> ZenohSettings:
        env = os.environ if env is None else env
        return cls(
            mode=_get(env, "PNAV_ZENOH_MODE", cls.mode),
            connect=_list(env, "PNAV_ZENOH_CONNECT", cls.connect),
            listen=_list(env, "PNAV_ZENOH_LISTEN", cls.listen),
            multicast=_bool(env, "PNAV_ZENOH_MULTICAST", cls.multicast),
            config_file=env.get("PNAV_ZENOH_CONFIG") or None,
            user=env.get("PNAV_ZENOH_USER", "").strip() or None,
            password=env.get("PNAV_ZENOH_PASSWORD") or None,
            users_file=env.get("PNAV_ZENOH_USERS_FILE") or None,
            data_queue=_int(env, "PNAV_ZENOH_DATA_QUEUE", cls.data_queue, minimum=1),
        )

    def to_env(self) -> dict[str, str]:
        """The variables that make a child process's ``from_env()`` equal to this."""
        out = {
            "PNAV_ZENOH_MODE": self.mode,
            "PNAV_ZENOH_CONNECT": ",".join(self.connect),
            "PNAV_ZENOH_LISTEN": ",".join(self.listen),
            "PNAV_ZENOH_MULTICAST": "true" if self.multicast else "false",
            "PNAV_ZENOH_DATA_QUEUE": str(self.data_queue),
        }
        if self.config_file:
            out["PNAV_ZENOH_CONFIG"] = self.config_file
        if self.user and self.password:
            out["PNAV_ZENOH_USER"] = self.user
            out["PNAV_ZENOH_PASSWORD"] = self.password
        if self.users_file:
            out["PNAV_ZENOH_USERS_FILE"] = self.users_file
        return out


@dataclass(frozen=True)
class EngineSettings:
    """The thesis' F, N and P (section 3.2), with navigation defaults."""

    period_s: float = 0.050
    max_rules: int = 1000
    pause_s: float = 0.0
    # one rule's run longer than this is logged (docs/ENGINE.md, "Bounded work")
    rule_budget_s: float = 0.050

    def __post_init__(self) -> None:
        if self.period_s <= 0:
            raise ConfigError(f"the activation period F must be positive, got {self.period_s}")
        if self.max_rules < 1:
            raise ConfigError(f"N (most rules per activation) must be >= 1, got {self.max_rules}")
        if self.pause_s < 0:
            raise ConfigError(f"the pause P must not be negative, got {self.pause_s}")
        if self.rule_budget_s <= 0:
            raise ConfigError(f"a rule's time budget must be positive, got {self.rule_budget_s}")

    @classmethod
    def from_env(cls, env: Env | None = None) -> EngineSettings:
        env = os.environ if env is None else env
        return cls(
            period_s=_float(env, "PNAV_ENGINE_PERIOD_MS", cls.period_s * 1000, minimum=0.1) / 1000,
            max_rules=_int(env, "PNAV_ENGINE_MAX_RULES", cls.max_rules, minimum=1),
            pause_s=_float(env, "PNAV_ENGINE_PAUSE_MS", cls.pause_s * 1000) / 1000,
            rule_budget_s=_float(
                env, "PNAV_ENGINE_RULE_BUDGET_MS", cls.rule_budget_s * 1000, minimum=0.1
            )
            / 1000,
        )


@dataclass(frozen=True)
class LeaseSettings:
    """How replicas of a scenario service split the robots (common.lease, docs/REPLICAS.md)."""

    enabled: bool = True
    period_s: float = 0.5
    timeout_s: float = 5.0

    def __post_init__(self) -> None:
        if self.period_s <= 0:
            raise ConfigError(f"the lease period must be positive, got {self.period_s}")
        if self.timeout_s < 4 * self.period_s:
            raise ConfigError(
                f"PNAV_LEASE_TIMEOUT_S={self.timeout_s} must be at least 4 lease periods "
                f"({4 * self.period_s} s): a replica renews its session every period"
            )

    @classmethod
    def from_env(cls, env: Env | None = None) -> LeaseSettings:
        env = os.environ if env is None else env
        return cls(
            enabled=_bool(env, "PNAV_LEASES", cls.enabled),
            period_s=_float(env, "PNAV_LEASE_PERIOD_MS", cls.period_s * 1000, minimum=10) / 1000,
            timeout_s=_float(env, "PNAV_LEASE_TIMEOUT_S", cls.timeout_s, minimum=1.0),
        )


def lockstep_from_env(env: Env | None = None) -> tuple[str, ...]:
    """PNAV_LOCKSTEP: a comma list of the services a lockstep sim waits for (docs/SIM.md,
    "Lockstep"); empty or unset: no lockstep."""
    env = os.environ if env is None else env
    names = tuple(n.strip() for n in env.get("PNAV_LOCKSTEP", "").split(",") if n.strip())
    for name in names:
        if not keys.valid_id(name):
            raise ConfigError(f"PNAV_LOCKSTEP: {name!r} is not a service name")
    return names


def default_instance() -> str:
    return f"{socket.gethostname()}-{os.getpid()}".replace(".", "-")


@dataclass(frozen=True)
class ServiceConfig:
    """Everything a scenario service needs to start."""

    service: str
    database_url: str
    zenoh: ZenohSettings = field(default_factory=ZenohSettings)
    engine: EngineSettings = field(default_factory=EngineSettings)
    leases: LeaseSettings = field(default_factory=LeaseSettings)
    pool_max: int = 4
    db_wait_s: float = 10.0
    # Postgres' lock_timeout for every statement of the service's pool: a people's lock (the
    # people's role may UPDATE some tables, so LOCK them) fails a blocked statement fast,
    # and its rule is run again at the next activation, instead of stalling the engine
    db_lock_timeout_ms: int = 200
    stats_period_s: float = 2.0
    instance: str = field(default_factory=default_instance)
    log_level: str = "INFO"
    # PNAV_LOCKSTEP: the services a lockstep sim waits for; non-empty: this one takes part
    lockstep: tuple[str, ...] = ()
    # PNAV_NOTIFY_IMAGES: notifications carry the committed row's image (CONTRACT.md, "Row
    # images"); off: hints only, every reader queries the table (a fallback test, or a
    # network where payload size matters more than a round trip)
    notify_images: bool = True

    @classmethod
    def from_env(cls, service: str, env: Env | None = None) -> ServiceConfig:
        env = os.environ if env is None else env
        url = env.get("PNAV_DATABASE_URL", "").strip()
        if not url:
            raise ConfigError(
                "PNAV_DATABASE_URL is not set: point it at the contract database "
                "(postgresql://user:pass@host:5432/db), or start the stack with `pnav up`"
            )
        return cls(
            service=service,
            database_url=url,
            zenoh=ZenohSettings.from_env(env),
            engine=EngineSettings.from_env(env),
            leases=LeaseSettings.from_env(env),
            pool_max=_int(env, "PNAV_DB_POOL_MAX", cls.pool_max, minimum=1),
            db_wait_s=_float(env, "PNAV_DB_WAIT_S", cls.db_wait_s),
            db_lock_timeout_ms=_int(env, "PNAV_DB_LOCK_TIMEOUT_MS", cls.db_lock_timeout_ms),
            stats_period_s=_float(env, "PNAV_STATS_PERIOD_S", cls.stats_period_s, minimum=0.1),
            instance=_get(env, "PNAV_INSTANCE", default_instance()),
            log_level=_get(env, "PNAV_LOG_LEVEL", cls.log_level).upper(),
            lockstep=lockstep_from_env(env),
            notify_images=_bool(env, "PNAV_NOTIFY_IMAGES", cls.notify_images),
        )

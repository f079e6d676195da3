"""Local infrastructure for one machine: an embedded Postgres and an in-process Zenoh router.

``pnav`` commands use this to run with no server installed: Postgres comes from the
``pgserver`` package (a real server, started in a data directory), unless
``PNAV_DATABASE_URL`` names one; the router listens on loopback only. The embedded one is
looked after (common.postmaster): restarted on the same data directory if it dies, and
stopped (its temporary data directory removed) by a watcher if this process dies first.
A server named by ``PNAV_DATABASE_URL`` is not ours: neither is done to it.

Least privilege (common.contract.roles, docs/DEPLOY.md): the launcher connects as the
server's superuser only to set the database up; every service then connects as its own role
(``LocalStack.url_for``), with a password made for this run. The embedded server listens on
a Unix socket in a directory only this OS user can open; on it the superuser ``postgres``
keeps ``trust`` (pgserver's own tooling and restarts use it), every other role must give its
password (scram-sha-256).

Zenoh between the local processes (:class:`LocalZenoh`, ``PNAV_LOCAL_ZENOH``): by default
each process is a *client* of the launcher's router, as in compose, and the router is the
one door: it checks every session's user and password (:class:`BusCredentials`) and lets
each identity put only its own keys, with the compose router's access control
(common.contract.acl.router_config: one source for both). As Postgres's roles get passwords
made for the run, so does every identity on the bus (the sim, each service, ``user`` for
people's tools), in a user/password file only this OS user can read: a process not given a
password cannot join, and one given ``user``'s (the CLI's, ``pnav env user``) can put goals,
user commands and strategies, never a sensor message, a ``cmd_vel`` or a service's
notification. The trust boundary for joining is the OS user, as for the Postgres socket.

``PNAV_LOCAL_ZENOH=peer`` makes each process a *peer* that learns the others' loopback
endpoints from the router (gossip) and sends to them directly: one TCP link instead of two
(docs/BENCHMARKS.md, "Peer-to-peer Zenoh"). It is an explicit opt-out of the bus's
defences: peers run WITHOUT authentication and so WITHOUT access control (a peer-to-peer
link does not go through the router; a peer's rules could only name identities nobody
proved). With user and password on every peer, zenoh 1.x sometimes never completes a
gossiped peer-to-peer link while the machine is busy (2 of 14 pairs never linked with both
cores loaded, silently; 0 of 12 without authentication, 0 of 12 as clients of an
authenticating router), which left a service deaf to the sim. Any process on the machine
may then put any key, ``cmd_vel`` included; the launcher says so in a warning.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import logging
import os
import secrets
import shutil
import tempfile
import time
from collections.abc import AsyncIterator, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import asyncpg
from zenoh import Session

from common.bus import start_router
from common.config import DATA_QUEUE_BATCHES, ZenohSettings
from common.contract import acl
from common.contract.grants import BUS_IDENTITIES, LOGIN_ROLES, USER, role_name
from common.contract.migrate import apply_migrations, contract_migrations
from common.contract.roles import bootstrap, is_superuser, role_url
from common.errors import ConfigError
from common.pgtemplate import Seeded, leave_spare, seed_from_template
from common.postmaster import Keeper, Lifeline, start_lifeline
from pnav.run.embedded_postgres import EmbeddedPostgres, free_port

# Every local peer listens on loopback only, on a port of the kernel's choosing: the router
# tells the others where (gossip), so nothing needs a fixed port but the router.
PEER_LISTEN: tuple[str, ...] = ("tcp/127.0.0.1:0",)


@dataclass(frozen=True)
class LocalZenoh:
    """How the processes of a local stack reach each other over Zenoh."""

    # client: every message through the router, which authenticates each session and applies
    # the access control; peer: directly, the router as rendezvous, with neither (see the
    # module docstring)
    mode: str = "client"
    # every link's data queue, the router's included (PNAV_ZENOH_DATA_QUEUE, common.config)
    data_queue: int = DATA_QUEUE_BATCHES

    def __post_init__(self) -> None:
        if self.mode not in ("peer", "client"):
            raise ConfigError(f"PNAV_LOCAL_ZENOH={self.mode!r} must be peer or client")

    @classmethod
    def from_env(cls, env: Mapping[str, str] | None = None) -> LocalZenoh:
        env = os.environ if env is None else env
        return cls(
            mode=env.get("PNAV_LOCAL_ZENOH", "").strip().lower() or cls.mode,
            data_queue=ZenohSettings.from_env(env).data_queue,
        )

    @property
    def authenticated(self) -> bool:
        """Whether the stack's router checks users and passwords, and what each may put,
        in this mode."""
        return self.mode == "client"

    def settings(self, router: str) -> ZenohSettings:
        """The Zenoh settings of a local process, given the router's endpoint."""
        if self.mode == "client":
            return ZenohSettings(mode="client", connect=(router,), data_queue=self.data_queue)
        return ZenohSettings(
            mode="peer",
            connect=(router,),
            listen=PEER_LISTEN,
            multicast=False,
            data_queue=self.data_queue,
        )


@dataclass(frozen=True)
class BusCredentials:
    """This run's Zenoh users: one per identity on the bus, with a fresh password each, and
    the ``user:password`` file the router checks every session against."""

    users_file: Path
    passwords: Mapping[str, str] = field(repr=False)

    @classmethod
    def create(cls, directory: Path, hosts: tuple[str, ...] = acl.DEFAULT_HOSTS) -> BusCredentials:
        """Make the passwords and write the file (mode 0600) in ``directory``: one per
        identity on the bus and per host identity in ``hosts`` (acl.host_identity)."""
        passwords = {who: secrets.token_hex(16) for who in (*BUS_IDENTITIES, *hosts)}
        path = directory / "zenoh-users.txt"
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "w") as out:
            out.writelines(f"{who}:{pw}\n" for who, pw in passwords.items())
        return cls(path, passwords)

    def identity(self, name: str) -> str:
        """The bus identity of a process: a service's own (a replica's or replacement's is
        its service's: ``planner-2`` is ``planner``), else ``user`` (the CLI, the
        dashboard, the recorder, tests and benchmarks act for people)."""
        if name in self.passwords:
            return name
        base = name.rsplit("-", 1)[0]
        return base if base in self.passwords else USER

    def apply(self, settings: ZenohSettings, name: str) -> ZenohSettings:
        """``settings`` authenticated as ``name``'s identity."""
        who = self.identity(name)
        return replace(settings, user=who, password=self.passwords[who])


@dataclass
class LocalStack:
    database_url: str
    zenoh: ZenohSettings
    router: Session
    postgres: EmbeddedPostgres | None
    keeper: Keeper | None = None
    # role (short name: "planner", "user") -> the DSN to connect as it; empty when the
    # server's account given could not set roles up (every process then uses database_url)
    role_urls: dict[str, str] = field(default_factory=dict)
    # None: the router accepts anyone and checks no put (peer mode)
    bus: BusCredentials | None = None
    # how long each step of setting it up took, seconds (pnav bench startup): postgres_dir
    # (the data directory made: copied, or by initdb), postgres_start (the server started,
    # pgserver's pg_ctl), router, roles (roles, passwords, migrations, grants); and whether
    # the data directory came from the template cluster (common.pgtemplate: "spare", a copy
    # made when an earlier stack stopped, or "copy") rather than from initdb (None)
    phases: dict[str, float] = field(default_factory=dict)
    seeded: Seeded | None = None

    def env(self) -> dict[str, str]:
        """The variables a process needs to join this stack (as the setup account: tests and
        benchmarks; a service gets its own role's DSN from :meth:`url_for`)."""
        return {"PNAV_DATABASE_URL": self.database_url, **self.zenoh.to_env()}

    def url_for(self, role: str) -> str:
        """The DSN of ``role`` (a service's name, or ``user`` for people)."""
        return self.role_urls.get(role, self.database_url)

    def zenoh_for(self, name: str) -> ZenohSettings:
        """The Zenoh settings of process ``name`` (a service, or anything acting for people:
        ``zenoh``, which :meth:`env` gives, is ``user``'s)."""
        return self.zenoh if self.bus is None else self.bus.apply(self.zenoh, name)


_PASSWORD_HBA = """\
# written by proactive-nav (pnav/run/local_stack.py): the superuser keeps trust on this private
# socket (pgserver's tooling uses it), every other role gives its password
local   all   postgres   trust
local   all   all        scram-sha-256
"""


async def _set_up_roles(conn: asyncpg.Connection, url: str) -> dict[str, str]:
    """Create the roles with fresh passwords, migrate as pnav_owner, grant; return each
    role's DSN. A non-superuser account gets the migrations only, and a warning."""
    if not await is_superuser(conn):
        await apply_migrations(conn)
        logging.getLogger("pnav.roles").warning(
            "PNAV_DATABASE_URL's user is not a superuser: every service connects as it "
            "(no per-service roles; docs/DEPLOY.md, Least privilege)"
        )
        return {}
    passwords = {role: secrets.token_hex(16) for role in LOGIN_ROLES}
    await bootstrap(conn, passwords)
    return {role: role_url(url, role_name(role), pw) for role, pw in passwords.items()}


def _contract_version() -> str:
    """What a template cluster's schema is: every migration's checksum."""
    return ",".join(m.checksum for m in contract_migrations())


def _migrate_template(dsn: str) -> None:
    """Give a template cluster the contract's roles (no passwords: each stack sets its own,
    common.contract.roles.ensure_roles), migrations and grants, as a stack's start would.
    Called from the running loop's thread: on a loop of its own, in a thread."""

    async def migrate() -> None:
        conn = await asyncpg.connect(dsn)
        try:
            await bootstrap(conn, {})
        finally:
            await conn.close()

    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        pool.submit(asyncio.run, migrate()).result()


def _require_passwords(data_dir: Path) -> None:
    """Ask every role but the superuser for its password (read at the next reload)."""
    (data_dir / "pg_hba.conf").write_text(_PASSWORD_HBA)


def _stop_postgres(postgres: EmbeddedPostgres, seeded: Seeded | None) -> None:
    """Stop the server; a cluster from the template then leaves the next stack's cluster
    ready (common.pgtemplate's spare), copied now that this one's server is down."""
    postgres.stop()
    if seeded is not None:
        leave_spare(_contract_version())


@contextlib.asynccontextmanager
async def local_stack(
    data_dir: Path | None = None,
    zenoh_port: int | None = None,
    local_zenoh: LocalZenoh | None = None,
    bus: BusCredentials | None = None,
    ros_domains: tuple[int, ...] = (),
    hosts: tuple[str, ...] = acl.DEFAULT_HOSTS,
) -> AsyncIterator[LocalStack]:
    """Start Postgres (embedded unless PNAV_DATABASE_URL is set) and a router; migrate.
    ``local_zenoh``: how the stack's processes use Zenoh (default: PNAV_LOCAL_ZENOH);
    ``bus``: the Zenoh users to use (if None: made for this run and removed after it, or
    none at all in peer mode); ``ros_domains``: the ROS 2 domains the router carries for a
    ROS 2 robot link with no rmw_zenoh router of its own (common.contract.acl); ``hosts``:
    the host identities of the processes running several services (pnav.run.host), each with
    exactly its services' permissions (common.contract.acl.host_identity)."""
    local_zenoh = local_zenoh if local_zenoh is not None else LocalZenoh.from_env()
    postgres: EmbeddedPostgres | None = None
    lifeline: Lifeline | None = None
    keeper: Keeper | None = None
    url = os.environ.get("PNAV_DATABASE_URL", "").strip()
    phases: dict[str, float] = {}
    seeded: Seeded | None = None
    started = time.monotonic()
    if not url:
        # pgserver narrates every pg_ctl run at INFO; a restart would repeat all of it
        logging.getLogger("pgserver").setLevel(logging.WARNING)
        postgres = EmbeddedPostgres(data_dir)
        lifeline = start_lifeline(postgres.data_dir, temporary=postgres.temporary)
        try:
            if postgres.temporary:
                # a copy of a cluster made once (initdb, then the contract's migrations),
                # not initdb and every migration for each stack (common.pgtemplate)
                seeded = seed_from_template(
                    postgres.data_dir, variant=_contract_version(), prepare=_migrate_template
                )
            phases["postgres_dir"] = time.monotonic() - started
            postgres.start()
        except BaseException:
            postgres.stop()
            lifeline.close()
            raise
        url = postgres.dsn()
        _require_passwords(postgres.data_dir)
        keeper = Keeper(postgres)
        phases["postgres_start"] = time.monotonic() - started - phases["postgres_dir"]
    stop_keeper = asyncio.Event()
    keeping: asyncio.Task[None] | None = None
    secret_dir: Path | None = None
    try:
        if bus is None and local_zenoh.authenticated:
            secret_dir = Path(tempfile.mkdtemp(prefix="pnav-bus-"))  # 0700: this OS user's
            bus = BusCredentials.create(secret_dir, hosts)
        elif bus is None:
            logging.getLogger("pnav.stack").warning(
                "PNAV_LOCAL_ZENOH=peer: the local Zenoh runs without authentication and "
                "without access control: any process on this machine may join it and put any "
                "key, sensor messages and cmd_vel included (docs/DEPLOY.md)"
            )
        endpoint = f"tcp/127.0.0.1:{zenoh_port or free_port()}"
        started = time.monotonic()
        router = start_router(
            (endpoint,),
            str(bus.users_file) if bus is not None else None,
            data_queue=local_zenoh.data_queue,
            ros_domains=ros_domains,
            hosts=hosts,
        )
        phases["router"] = time.monotonic() - started
        try:
            started = time.monotonic()
            conn = await asyncpg.connect(url)
            try:
                if postgres is not None:
                    await conn.execute("SELECT pg_reload_conf()")  # _require_passwords
                role_urls = await _set_up_roles(conn, url)
            finally:
                await conn.close()
            phases["roles"] = time.monotonic() - started
            if keeper is not None:
                keeping = asyncio.create_task(keeper.run(stop_keeper), name="postgres-keeper")
            zenoh = local_zenoh.settings(endpoint)
            zenoh = bus.apply(zenoh, USER) if bus is not None else zenoh
            yield LocalStack(url, zenoh, router, postgres, keeper, role_urls, bus, phases, seeded)
        finally:
            stop_keeper.set()
            if keeping is not None:
                await keeping  # a restart under way ends before the server is stopped
            router.close()
    finally:
        if secret_dir is not None:
            shutil.rmtree(secret_dir, ignore_errors=True)
        if postgres is not None:
            _stop_postgres(postgres, seeded)
        if lifeline is not None:
            lifeline.close()

"""The fleet deployment (deploy/), checked without a Docker engine.

- deploy/docker-compose.yml: valid against the Compose Specification's JSON schema (the copy
  the check-jsonschema package ships), every service of the stack present, images pinned,
  only PNAV_* variables the code reads, scalable scenario services, health checks and
  restart policies, the dependencies on Postgres, the router and the migration.
- Its health check command really finds a running service's liveliness token (a service
  process started as the compose file starts it, with PNAV_INSTANCE unset).
- deploy/zenoh/router.json5: parsed by Zenoh itself, and a router opened from it works.
- deploy/Dockerfile: pinned base, non-root, only existing COPY sources, no test extras.
- docs/DEPLOY.md documents every variable the code reads and every compose variable.
- `docker compose config` when a docker client with the compose plugin is present.
"""

from __future__ import annotations

import ast
import asyncio
import importlib
import importlib.metadata
import importlib.resources
import json
import os
import re
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import time
import tomllib
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import asyncpg
import jsonschema
import pytest
import yaml
import zenoh
from packaging.specifiers import SpecifierSet

from common import bus
from common.config import ServiceConfig, ZenohSettings, default_instance
from common.contract import acl, keys
from common.contract.grants import role_name
from common.contract.roles import bootstrap, role_url
from common.errors import UsageError
from pnav.run.credentials import (
    DB_PASSWORDS,
    SUPERUSER_PASSWORD,
    ZENOH_PASSWORDS,
    ZENOH_USERS_FILE,
)
from pnav.run.embedded_postgres import free_port
from pnav.run.stack_options import SCENARIO_SERVICES, StackOptions

ROOT = Path(__file__).resolve().parents[2]
DEPLOY = ROOT / "deploy"
COMPOSE_FILE = DEPLOY / "docker-compose.yml"
DOCKERFILE = DEPLOY / "Dockerfile"
ROUTER_CONFIG = DEPLOY / "zenoh" / "router.json5"
DEPLOY_DOC = ROOT / "docs" / "DEPLOY.md"

COMPONENTS = ("sim", "bridge", *SCENARIO_SERVICES, "dashboard")
# the one component that publishes a port (the web page, on the host's loopback)
DASHBOARD_PORT = "8080"
INFRASTRUCTURE = ("postgres", "zenoh", "migrate")


def identity_of(component: str) -> str:
    """The role and Zenoh user a component connects as: its own, but for the dashboard,
    which writes only people's rows and so acts as people do."""
    return "user" if component == "dashboard" else component


# where each component's code names itself (its liveliness token is pnav/alive/<name>/...)
SERVICE_NAMES = {
    "sim": ("services.sim.node", "SERVICE"),
    "bridge": ("services.bridge.bridge", "SERVICE"),
    "strategy": ("services.strategy.service", "StrategyService.service"),
    "planner": ("services.planner.service", "PlannerService.service"),
    "controller": ("services.controller.service", "ControllerService.service"),
    "decision": ("services.decision.service", "DecisionService.service"),
    "dashboard": ("services.dashboard.service", "SERVICE"),
}
PNAV_NAME = re.compile(r"PNAV_[A-Z0-9_]*[A-Z0-9]")
PINNED_TAG = re.compile(r"^\d+(\.\d+)+(-[A-Za-z0-9.]+)?$")


# -- helpers ---------------------------------------------------------------------------------


def compose() -> dict[str, Any]:
    doc = yaml.safe_load(COMPOSE_FILE.read_text())
    assert isinstance(doc, dict)
    return doc


def services() -> dict[str, dict[str, Any]]:
    result: dict[str, dict[str, Any]] = compose()["services"]
    return result


_VARIABLE = re.compile(r"\$\$|\$\{([A-Za-z_][A-Za-z0-9_]*)(?:(:?[-?])([^{}$]*))?\}")
# What `pnav secrets` writes to deploy/.env: the passwords the compose file has no default for.
SECRETS = {
    SUPERUSER_PASSWORD: "pw-superuser",
    **{var: f"pw-{role}-db" for role, var in DB_PASSWORDS.items()},
    **{var: f"pw-{user}-zenoh" for user, var in ZENOH_PASSWORDS.items()},
    ZENOH_USERS_FILE: "./zenoh-users.txt",
}


class Unset(Exception):
    """A ${VAR:?message} whose variable is unset: `docker compose` stops with the message."""


def interpolate(value: str, env: Mapping[str, str] | None = None) -> str:
    """Compose's interpolation for the forms this file uses: $$, ${VAR}, ${VAR:-d}, ${VAR-d},
    ${VAR:?message}.

    ``env`` plays the shell, on top of the secrets `pnav secrets` writes (``SECRETS``); left
    out, every other variable takes its default. ``secrets=False``-style checks pass an
    ``env`` with a secret set to "" to see the refusal. Any other use of ``$`` fails, so a
    form this helper does not know is not skipped.
    """
    env = {**SECRETS, **(env or {})}

    def one(match: re.Match[str]) -> str:
        if match.group(0) == "$$":
            return "$"
        name, operator, default = match.groups()
        value = env.get(name)
        if operator == ":-" and not value:
            return default
        if operator == "-" and value is None:
            return default
        if operator == ":?" and not value:
            raise Unset(f"{name}: {default}")
        return value or ""

    plain = _VARIABLE.sub(lambda m: "" if m.group(0) == "$$" else "x", value)
    assert "$" not in plain, f"interpolation form not understood in {value!r}"
    return _VARIABLE.sub(one, value)


def interpolated(node: Any, env: Mapping[str, str] | None = None) -> Any:
    if isinstance(node, str):
        return interpolate(node, env)
    if isinstance(node, list):
        return [interpolated(item, env) for item in node]
    if isinstance(node, dict):
        return {key: interpolated(item, env) for key, item in node.items()}
    return node


def environment(service: Mapping[str, Any]) -> dict[str, str]:
    """A service's environment as a dict, whichever of the two Compose forms it uses."""
    env = service.get("environment") or {}
    if isinstance(env, list):
        return dict(item.split("=", 1) if "=" in item else (item, "") for item in env)
    return {key: "" if value is None else str(value) for key, value in env.items()}


def strings(node: Any) -> Iterator[str]:
    if isinstance(node, str):
        yield node
    elif isinstance(node, list):
        for item in node:
            yield from strings(item)
    elif isinstance(node, dict):
        for key, item in node.items():
            yield from strings(key)
            yield from strings(item)


def compose_variables() -> set[str]:
    """Every variable the compose file takes from the shell (${NAME...}), comments aside."""
    return {
        m.group(1)
        for text in strings(compose())
        for m in _VARIABLE.finditer(text)
        if m.group(0) != "$$"
    }


def code_variables() -> dict[str, set[str]]:
    """Every PNAV_* variable named in the code as a string of its own, with where."""
    found: dict[str, set[str]] = {}
    for package in ("common", "services", "pnav"):
        for path in sorted((ROOT / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
                if (
                    isinstance(node, ast.Constant)
                    and isinstance(node.value, str)
                    and PNAV_NAME.fullmatch(node.value)
                ):
                    found.setdefault(node.value, set()).add(str(path.relative_to(ROOT)))
    return found


def split_image(image: str) -> tuple[str, str | None]:
    name, _, digest = image.partition("@")
    last = name.rsplit("/", 1)[-1]
    if ":" in last:
        repository, tag = name.rsplit(":", 1)
        return repository, tag
    return name, None if not digest else "@" + digest


def dockerfile_instructions() -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) of deploy/Dockerfile, continuation lines joined."""
    instructions: list[tuple[str, str]] = []
    pending = ""
    for raw in DOCKERFILE.read_text().splitlines():
        line = raw.strip()
        if not pending and (not line or line.startswith("#")):
            continue
        if line.startswith("#"):
            continue
        if line.endswith("\\"):
            pending += line[:-1] + " "
            continue
        full = (pending + line).strip()
        pending = ""
        keyword, _, rest = full.partition(" ")
        instructions.append((keyword.upper(), rest.strip()))
    assert not pending, "the Dockerfile ends inside a continued line"
    return instructions


def pyproject() -> dict[str, Any]:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


def health_command(service: str) -> list[str]:
    """The service's health check, as the container would run it (Compose's $$ undone)."""
    test = interpolated(services()[service]["healthcheck"]["test"])
    assert isinstance(test, list) and test[0] == "CMD", test
    return [sys.executable if test[1] == "python" else test[1], *test[2:]]


def run_health_check(service: str, env: Mapping[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        health_command(service),
        cwd=ROOT,
        env=dict(env),
        capture_output=True,
        text=True,
        timeout=30,
    )


def base_env() -> dict[str, str]:
    """This process's environment without any PNAV_* variable (a container has none but its
    compose environment)."""
    return {key: value for key, value in os.environ.items() if not key.startswith("PNAV_")}


# -- the compose file ------------------------------------------------------------------------


def compose_schema() -> dict[str, Any]:
    vendor = importlib.resources.files("check_jsonschema.builtin_schemas.vendor")
    schema: dict[str, Any] = json.loads(vendor.joinpath("compose-spec.json").read_text())
    return schema


def schema_errors(document: Any) -> list[str]:
    schema = compose_schema()
    validator = jsonschema.validators.validator_for(schema)(schema)
    return [f"{e.json_path}: {e.message}" for e in validator.iter_errors(document)]


def test_the_compose_file_follows_the_compose_specification_schema() -> None:
    assert schema_errors(compose()) == []
    assert schema_errors(interpolated(compose())) == []


def test_the_schema_check_does_catch_a_mistake() -> None:
    broken = compose()
    broken["services"]["planner"]["restart_policy"] = "always"  # not a Compose key
    broken["services"]["sim"]["depends_on"] = {"postgres": {"condition": "healthy"}}
    errors = schema_errors(broken)
    assert any("restart_policy" in e for e in errors), errors
    assert any("depends_on" in e for e in errors), errors


def test_every_service_of_the_stack_is_there() -> None:
    assert set(services()) == {*INFRASTRUCTURE, *COMPONENTS}
    # the same services `pnav up` starts (the dashboard unless --no-dashboard), each run the
    # way the launcher runs it
    assert set(StackOptions().services) | {"dashboard"} == set(COMPONENTS)
    for name in COMPONENTS:
        assert services()[name]["command"] == ["python", "-m", f"services.{name}"]
        assert (ROOT / "services" / name / "__main__.py").is_file()


@pytest.mark.parametrize("name", COMPONENTS)
def test_each_health_check_asks_for_the_name_the_service_announces(name: str) -> None:
    module, attribute = SERVICE_NAMES[name]
    value: Any = importlib.import_module(module)
    for part in attribute.split("."):
        value = getattr(value, part)
    test = services()[name]["healthcheck"]["test"]
    assert test[:3] == ["CMD", "python", "-c"]
    assert test[-1] == value == name


def test_every_image_is_pinned() -> None:
    version = pyproject()["project"]["version"]
    for name, service in services().items():
        assert "image" in service, f"{name} has no image"
        _repository, tag = split_image(service["image"])
        assert tag is not None, f"{name}: {service['image']} has no tag"
        assert tag != "latest", f"{name}: {service['image']} is not pinned"
        if "build" in service:
            # the image built from deploy/Dockerfile is tagged with the project's version
            assert service["image"] == f"proactive-nav:{version}", name
        else:
            assert PINNED_TAG.match(tag), f"{name}: {tag!r} is not a full version"


def test_the_router_image_speaks_the_protocol_of_the_python_package() -> None:
    repository, tag = split_image(services()["zenoh"]["image"])
    assert repository == "eclipse/zenoh"
    assert tag is not None
    package = importlib.metadata.version("eclipse-zenoh")
    # Zenoh keeps one wire protocol across 1.x; the pinned router is a 1.x release too
    assert tag.split(".")[0] == package.split(".")[0], (tag, package)


def test_every_built_service_uses_deploy_dockerfile_from_the_repository_root() -> None:
    built = {name: s["build"] for name, s in services().items() if "build" in s}
    assert set(built) == {"migrate", *COMPONENTS}
    for name, build in built.items():
        context = (DEPLOY / build["context"]).resolve()
        assert context == ROOT, name
        assert (context / build["dockerfile"]).resolve() == DOCKERFILE, name


def test_every_pnav_variable_the_compose_file_sets_is_read_by_the_code() -> None:
    read = code_variables()
    for name, service in services().items():
        for variable in environment(service):
            if variable.startswith("PNAV_"):
                assert variable in read, f"{name} sets {variable}, which no code reads"
    for variable in compose_variables():
        if variable.startswith("PNAV_"):
            assert variable in read, f"${{{variable}}} is not a variable the code reads"


def test_the_variable_scan_sees_every_place_the_code_reads_variables() -> None:
    read = code_variables()
    assert "common/config.py" in read["PNAV_ZENOH_CONNECT"]
    assert "services/sim/__main__.py" in read["PNAV_SIM_ROBOTS"]
    assert "services/bridge/settings.py" in read["PNAV_BRIDGE_WATCHDOG_S"]
    assert "pnav/run/stackfile.py" in read["PNAV_STATE_DIR"]
    assert not any(name.endswith("_") for name in read)  # prefixes in docstrings are not names


def test_every_variable_is_documented_in_deploy_md() -> None:
    doc = DEPLOY_DOC.read_text()
    documented = set(re.findall(r"`([A-Z][A-Z0-9_]*)`", doc))
    missing_code = sorted(set(code_variables()) - documented)
    missing_compose = sorted(compose_variables() - documented)
    assert missing_code == [], f"read by the code, not in docs/DEPLOY.md: {missing_code}"
    assert missing_compose == [], f"used by the compose file, not documented: {missing_compose}"


def test_deploy_md_gives_the_commands() -> None:
    doc = DEPLOY_DOC.read_text()
    for command in (
        "docker compose -f deploy/docker-compose.yml up --build",
        "--scale controller=3",
        "docker compose -f deploy/docker-compose.yml exec planner pnav status",
        "PNAV_ZENOH_CONNECT=tcp/127.0.0.1:7447",
    ):
        assert command in doc, command


def test_each_component_reaches_postgres_as_its_own_role_and_the_router_as_its_own_user() -> None:
    postgres = environment(interpolated(services()["postgres"]))
    assert postgres["POSTGRES_USER"] == "postgres"
    assert postgres["POSTGRES_PASSWORD"] == SECRETS["POSTGRES_PASSWORD"]
    database = postgres["POSTGRES_DB"]
    migrate = environment(interpolated(services()["migrate"]))
    assert migrate["PNAV_DATABASE_URL"] == (
        f"postgresql://postgres:{SECRETS['POSTGRES_PASSWORD']}@postgres:5432/{database}"
    )
    for variable in DB_PASSWORDS.values():  # what the migrate job creates the roles with
        assert migrate[variable] == SECRETS[variable], variable
    for name in COMPONENTS:
        env = environment(interpolated(services()[name]))
        assert "PNAV_INSTANCE" not in env, f"{name}: replicas would share one instance id"
        identity = identity_of(name)
        assert env["PNAV_ZENOH_MODE"] == "client"
        assert env["PNAV_ZENOH_CONNECT"] == "tcp/zenoh:7447"
        assert env["PNAV_ZENOH_MULTICAST"] == "false"
        assert env["PNAV_ZENOH_USER"] == identity
        assert env["PNAV_ZENOH_PASSWORD"] == SECRETS[ZENOH_PASSWORDS[identity]]
        zenoh_settings = ZenohSettings(
            mode="client",
            connect=("tcp/zenoh:7447",),
            multicast=False,
            user=identity,
            password=SECRETS[ZENOH_PASSWORDS[identity]],
        )
        if name == "sim":  # it never connects to Postgres: no account at all
            assert "PNAV_DATABASE_URL" not in env
            assert ZenohSettings.from_env(env) == zenoh_settings
            continue
        password = SECRETS[DB_PASSWORDS[identity]]
        expected_url = f"postgresql://pnav_{identity}:{password}@postgres:5432/{database}"
        assert env["PNAV_DATABASE_URL"] == expected_url, name
        # the values are ones the services accept
        config = ServiceConfig.from_env(name, env)
        assert config.zenoh == zenoh_settings
        assert config.database_url == expected_url
        assert config.instance == default_instance()


def test_no_password_has_a_default_and_only_the_migration_is_superuser() -> None:
    required = {
        m.group(1)
        for text in strings(compose())
        for m in _VARIABLE.finditer(text)
        if m.group(2) == ":?"
    }
    # every secret: the dashboard's container is people's (pnav_user, Zenoh user `user`);
    # the host identity's is required by the composed alternative (tests/deploy/test_composed)
    assert required == set(SECRETS) - {"PNAV_ZENOH_PASSWORD_HOST"}
    for variable in compose_variables():
        if "PASSWORD" in variable or variable == ZENOH_USERS_FILE:
            assert variable in required, f"${{{variable}}} has a default"
    for variable in required:
        with pytest.raises(Unset, match=variable):
            interpolated(compose(), {variable: ""})
    for name, service in services().items():
        url = environment(interpolated(service)).get("PNAV_DATABASE_URL", "")
        user = url.partition("://")[2].partition(":")[0]
        own = "postgres" if name == "migrate" else f"pnav_{identity_of(name)}"
        assert user in ("", own), name


def test_the_shell_sets_the_database_name_and_the_passwords() -> None:
    shell = {"POSTGRES_DB": "nav", "PNAV_DB_PASSWORD_PLANNER": "s3cret"}
    assert environment(interpolated(services()["postgres"], shell))["POSTGRES_DB"] == "nav"
    url = environment(interpolated(services()["planner"], shell))["PNAV_DATABASE_URL"]
    assert url == "postgresql://pnav_planner:s3cret@postgres:5432/nav"


def test_pnav_secrets_writes_every_variable_the_compose_file_requires(tmp_path: Path) -> None:
    from common.contract import acl
    from common.contract.grants import BUS_IDENTITIES, LOGIN_ROLES
    from pnav.run.credentials import generate

    # one password per role of CONTRACT.md and per identity on the bus, none forgotten
    assert set(DB_PASSWORDS) == set(LOGIN_ROLES)
    assert set(ZENOH_PASSWORDS) == {*BUS_IDENTITIES, *acl.DEFAULT_HOSTS}
    env_file, users_file = generate(tmp_path)
    written = dict(line.split("=", 1) for line in env_file.read_text().splitlines() if "=" in line)
    assert set(written) == set(SECRETS)
    passwords = [v for k, v in written.items() if k != ZENOH_USERS_FILE]
    assert len(set(passwords)) == len(passwords) and all(len(p) >= 32 for p in passwords)
    users = dict(line.split(":", 1) for line in users_file.read_text().splitlines())
    assert users == {user: written[var] for user, var in ZENOH_PASSWORDS.items()}
    assert (tmp_path / written[ZENOH_USERS_FILE]).resolve() == users_file.resolve()
    assert env_file.stat().st_mode & 0o077 == 0 and users_file.stat().st_mode & 0o077 == 0
    with pytest.raises(UsageError, match="exists"):
        generate(tmp_path)


def test_the_sim_takes_world_rate_and_robots_from_the_shell(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    raw = environment(services()["sim"])
    for variable in ("PNAV_SIM_WORLD", "PNAV_SIM_RATE", "PNAV_SIM_ROBOTS"):
        assert raw[variable].startswith(f"${{{variable}:-"), raw[variable]

    from services.sim.__main__ import build, parse_args

    def sim_settings(shell: Mapping[str, str]) -> tuple[str, int, float]:
        env = environment(interpolated(services()["sim"], shell))
        for variable in [v for v in os.environ if v.startswith("PNAV_")]:
            monkeypatch.delenv(variable)
        for variable, value in env.items():
            monkeypatch.setenv(variable, value)
        # the image's working directory /app holds worlds/, as the repository root does
        monkeypatch.chdir(ROOT)
        world, _config, rate = build(parse_args([]))
        return world.name, len(world.robots), rate

    assert sim_settings({}) == ("warehouse", 2, 1.0)
    shell = {"PNAV_SIM_WORLD": "worlds/open_room.yaml", "PNAV_SIM_RATE": "5"}
    assert sim_settings({**shell, "PNAV_SIM_ROBOTS": "3"}) == ("open_room", 3, 5.0)


def test_scenario_services_can_be_scaled() -> None:
    for name in (n for n in COMPONENTS if n != "dashboard"):
        service = services()[name]
        for key in ("container_name", "ports", "hostname"):
            assert key not in service, f"{name} has {key}: it could not run as replicas"
        assert "replicas" not in (service.get("deploy") or {}), name


def test_only_postgres_the_router_and_the_dashboard_publish_ports_on_loopback() -> None:
    published = {name: s["ports"] for name, s in services().items() if "ports" in s}
    assert set(published) <= {"postgres", "zenoh", "dashboard"}
    assert "zenoh" in published, "pnav status on the host needs the router's port"
    assert "dashboard" in published, "the browser on the host needs the dashboard's port"
    container_port = {"postgres": "5432", "zenoh": "7447", "dashboard": DASHBOARD_PORT}
    for name, ports in published.items():
        for port in interpolated(ports):
            address, host_port, target = str(port).split(":")
            assert address == "127.0.0.1", f"{name} publishes beyond loopback by default"
            assert target == container_port[name] == host_port


def test_the_dashboard_listens_in_its_container_on_the_port_compose_publishes() -> None:
    from services.dashboard.settings import DashboardSettings

    settings = DashboardSettings.from_env(environment(interpolated(services()["dashboard"])))
    # every interface inside the container (the published port is the host's loopback only)
    assert settings.host == "0.0.0.0"
    (port,) = interpolated(services()["dashboard"]["ports"])
    assert str(settings.port) == port.split(":")[-1] == DASHBOARD_PORT


def test_every_service_has_a_health_check_and_a_restart_policy() -> None:
    for name, service in services().items():
        health = service.get("healthcheck")
        assert health is not None, f"{name} has no healthcheck"
        if name == "migrate":
            # a one-shot job: the services wait for its exit code, not for a health status
            assert health == {"disable": True}
            assert service["restart"] == "no"
            assert service["command"] == ["pnav", "migrate", "--roles", "--wait", "60"]
            continue
        assert service["restart"] == "unless-stopped", name
        assert health["test"][0] in ("CMD", "CMD-SHELL"), name
        for key in ("interval", "timeout", "retries"):
            assert key in health, f"{name}: healthcheck without {key}"


def test_the_components_wait_for_postgres_the_router_and_the_migration() -> None:
    expected = {
        "postgres": {"condition": "service_healthy"},
        "zenoh": {"condition": "service_healthy"},
        "migrate": {"condition": "service_completed_successfully"},
    }
    for name in COMPONENTS:
        assert services()[name]["depends_on"] == expected, name
    assert services()["migrate"]["depends_on"] == {"postgres": {"condition": "service_healthy"}}


def test_postgres_keeps_its_data_in_a_named_volume() -> None:
    postgres = services()["postgres"]
    volume, _, target = postgres["volumes"][0].partition(":")
    assert volume in compose()["volumes"]
    assert target == "/var/lib/postgresql/data"
    assert "pg_isready" in " ".join(postgres["healthcheck"]["test"])


def test_the_router_container_uses_the_mounted_config() -> None:
    zenoh_service = services()["zenoh"]
    source, target, mode = zenoh_service["volumes"][0].split(":")
    assert (DEPLOY / source).resolve() == ROUTER_CONFIG
    assert mode == "ro"
    assert zenoh_service["command"] == ["-c", target]
    # a TCP connect to the router's port, with the busybox of the Alpine-based image
    assert zenoh_service["healthcheck"]["test"][:3] == ["CMD", "/bin/busybox", "nc"]
    assert zenoh_service["healthcheck"]["test"][-1] == "7447"


# -- the health check against real processes -------------------------------------------------


@pytest.fixture
def router_endpoint(zenoh_settings: ZenohSettings) -> str:
    return zenoh_settings.connect[0]


def as_role(db_url: str, service: str) -> str:
    """``db_url`` set up with the roles (as the migrate job does), as ``service``'s role (this
    test server trusts its local connections: no password)."""

    async def set_up() -> None:
        conn = await asyncpg.connect(db_url)
        try:
            await bootstrap(conn)
        finally:
            await conn.close()

    asyncio.run(set_up())
    return role_url(db_url, role_name(service), None)


def check_env(endpoint: str, **extra: str) -> dict[str, str]:
    return {
        **base_env(),
        "PNAV_ZENOH_MODE": "client",
        "PNAV_ZENOH_CONNECT": endpoint,
        "PNAV_ZENOH_MULTICAST": "false",
        **extra,
    }


@pytest.fixture
def token_session(zenoh_settings: ZenohSettings) -> Iterator[zenoh.Session]:
    session = bus.open_session(zenoh_settings)
    try:
        yield session
    finally:
        session.close()


@pytest.fixture
def asker(zenoh_settings: ZenohSettings) -> Iterator[zenoh.Session]:
    """Another client, to see a token through the router before the check runs."""
    session = bus.open_session(zenoh_settings)
    try:
        yield session
    finally:
        session.close()


def wait_until_visible(asker: zenoh.Session, key: str, present: bool = True) -> None:
    deadline = time.monotonic() + 10
    while True:
        replies = asker.liveliness().get(key, timeout=2)
        if any(r.ok is not None for r in replies) == present:
            return
        assert time.monotonic() < deadline, f"{key} never {'appeared' if present else 'went'}"
        time.sleep(0.05)


def test_the_health_check_finds_a_token_of_this_host_only(
    router_endpoint: str, token_session: zenoh.Session, asker: zenoh.Session
) -> None:
    env = check_env(router_endpoint)
    missing = run_health_check("planner", env)
    assert missing.returncode == 1
    assert "no liveliness token pnav/alive/planner/" in missing.stderr

    # another container's replica does not make this one healthy
    other_key = keys.alive_key("planner", "otherhost-7")
    other = token_session.liveliness().declare_token(other_key)
    wait_until_visible(asker, other_key)
    assert run_health_check("planner", env).returncode == 1
    other.undeclare()

    # what a process here announces with PNAV_INSTANCE unset: <hostname>-<pid>
    mine_key = keys.alive_key("planner", default_instance())
    mine = token_session.liveliness().declare_token(mine_key)
    wait_until_visible(asker, mine_key)
    result = run_health_check("planner", env)
    assert result.returncode == 0, result.stderr
    assert run_health_check("decision", env).returncode == 1
    mine.undeclare()
    wait_until_visible(asker, mine_key, present=False)
    assert run_health_check("planner", env).returncode == 1


def test_the_health_check_honours_pnav_instance(
    router_endpoint: str, token_session: zenoh.Session, asker: zenoh.Session
) -> None:
    key = keys.alive_key("bridge", "bridge-a")
    token = token_session.liveliness().declare_token(key)
    try:
        wait_until_visible(asker, key)
        assert run_health_check("bridge", check_env(router_endpoint)).returncode == 1
        named = check_env(router_endpoint, PNAV_INSTANCE="bridge-a")
        assert run_health_check("bridge", named).returncode == 0
        other = check_env(router_endpoint, PNAV_INSTANCE="bridge-b")
        assert run_health_check("bridge", other).returncode == 1
    finally:
        token.undeclare()


def test_the_health_check_fails_without_a_router() -> None:
    env = check_env(f"tcp/127.0.0.1:{free_port()}")
    result = run_health_check("strategy", env)
    assert result.returncode != 0


@pytest.mark.slow
@pytest.mark.parametrize("name", ["strategy", "sim"])
def test_a_service_started_as_compose_starts_it_turns_healthy_then_not(
    name: str, db_url: str, acl_router_endpoint: str
) -> None:
    """The compose command and environment (hosts pointed at this test's Postgres, where it
    connects as its role, and at a router with the compose access control, where it logs in
    as its user), no PNAV_INSTANCE: the health check passes while the process runs, fails
    once it stops."""
    service = services()[name]
    env = {**base_env(), **environment(interpolated(service))}
    if name != "sim":
        env["PNAV_DATABASE_URL"] = as_role(db_url, name)
    env["PNAV_ZENOH_CONNECT"] = acl_router_endpoint
    command = [sys.executable if w == "python" else w for w in service["command"]]
    # cwd: the image's working directory /app holds worlds/, as the repository root does
    process = subprocess.Popen(
        command, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    try:
        deadline = time.monotonic() + 60
        while True:
            result = run_health_check(name, env)
            if result.returncode == 0:
                break
            assert process.poll() is None, f"{name} died: {process.communicate()[1][-2000:]}"
            assert time.monotonic() < deadline, f"never healthy: {result.stderr}"
            time.sleep(0.3)
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=30) == 0
        assert run_health_check(name, env).returncode == 1
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


# -- the router's config ---------------------------------------------------------------------


def test_the_router_config_is_what_zenoh_reads() -> None:
    config = zenoh.Config.from_file(str(ROUTER_CONFIG))
    assert json.loads(config.get_json("mode")) == "router"
    assert json.loads(config.get_json("listen/endpoints")) == ["tcp/0.0.0.0:7447"]
    assert json.loads(config.get_json("scouting/multicast/enabled")) is False
    assert json.loads(config.get_json("plugins")) == {}  # no REST plugin, no other


def test_a_router_from_the_config_carries_liveliness_between_clients(
    acl_router_endpoint: str,
) -> None:
    def settings(user: str) -> ZenohSettings:
        password = SECRETS[ZENOH_PASSWORDS[user]]
        return ZenohSettings(
            mode="client", connect=(acl_router_endpoint,), user=user, password=password
        )

    announcer = bus.open_session(settings("planner"))
    asker = bus.open_session(settings("user"))
    try:
        token = announcer.liveliness().declare_token(keys.alive_key("planner", "p-1"))
        deadline = time.monotonic() + 10
        while True:
            replies = asker.liveliness().get(keys.alive_watch("planner"), timeout=2)
            found = [str(r.ok.key_expr) for r in replies if r.ok is not None]
            if found:
                break
            assert time.monotonic() < deadline, "the token never reached the other client"
            time.sleep(0.1)
        assert found == ["pnav/alive/planner/p-1"]
        token.undeclare()
    finally:
        asker.close()
        announcer.close()


def test_the_router_authenticates_from_the_mounted_secret() -> None:
    zenoh_service = services()["zenoh"]
    assert zenoh_service["secrets"] == ["zenoh_users"]
    secret = interpolated(compose()["secrets"]["zenoh_users"])
    assert secret == {"file": SECRETS[ZENOH_USERS_FILE]}
    config = zenoh.Config.from_file(str(ROUTER_CONFIG))
    usrpwd = json.loads(config.get_json("transport/auth/usrpwd"))
    assert usrpwd["dictionary_file"] == "/run/secrets/zenoh_users" == acl.DICTIONARY_FILE
    control = json.loads(config.get_json("access_control"))
    assert control["enabled"] is True and control["default_permission"] == "deny"


# -- the Dockerfile --------------------------------------------------------------------------


def test_the_base_image_is_a_pinned_python_3_11_slim() -> None:
    bases = [args for keyword, args in dockerfile_instructions() if keyword == "FROM"]
    assert bases, "no FROM"
    for base in bases:
        image = base.split()[0]
        repository, tag = split_image(image)
        assert repository == "python", image
        assert tag is not None and re.fullmatch(r"3\.11\.\d+-slim(-[a-z]+)?", tag), image
        # the image's Python is one the project accepts
        assert SpecifierSet(pyproject()["project"]["requires-python"]).contains(tag.split("-")[0])


def test_the_image_runs_as_an_unprivileged_user() -> None:
    instructions = dockerfile_instructions()
    users = [args for keyword, args in instructions if keyword == "USER"]
    assert users and users[-1] not in ("root", "0", "0:0"), users
    last_user = max(i for i, (keyword, _) in enumerate(instructions) if keyword == "USER")
    assert all(keyword != "RUN" for keyword, _ in instructions[last_user:]), (
        "a RUN after the last USER would run as that user, or switch back"
    )
    assert any(keyword == "RUN" and "useradd" in args for keyword, args in instructions)


def test_every_copy_source_exists_and_the_package_is_complete() -> None:
    copied: set[str] = set()
    for keyword, args in dockerfile_instructions():
        if keyword in ("COPY", "ADD"):
            assert keyword == "COPY", "ADD fetches and unpacks: COPY is all this image needs"
            words = [w for w in shlex.split(args) if not w.startswith("--")]
            assert not args.startswith("--from"), args
            *sources, _destination = words
            for source in sources:
                path = (ROOT / source).resolve()
                assert path.is_relative_to(ROOT), f"{source} is outside the build context"
                assert path.exists(), f"COPY source {source} does not exist"
                copied.add(source.rstrip("/"))
    project = pyproject()
    packages = {
        pattern.rstrip("*")
        for pattern in project["tool"]["setuptools"]["packages"]["find"]["include"]
    }
    # examples/ is not installed: it sits in the working directory (tests/deploy/test_swap.py)
    needed = {"pyproject.toml", project["project"]["readme"], "worlds", "examples", *packages}
    assert copied == needed


def test_pip_installs_the_repository_without_test_extras() -> None:
    runs = [args for keyword, args in dockerfile_instructions() if keyword == "RUN"]
    installs = [r for r in runs if "pip install" in r]
    assert any(re.search(r"pip install \.(\s|$)", r) for r in installs), installs
    for run in installs:
        assert "[test]" not in run and "-e " not in run, run


def test_the_default_command_prints_help_and_health_checks_are_left_to_compose() -> None:
    instructions = dockerfile_instructions()
    assert all(keyword != "HEALTHCHECK" for keyword, _ in instructions)
    cmd = [json.loads(args) for keyword, args in instructions if keyword == "CMD"]
    assert cmd == [["pnav", "--help"]]
    assert "pnav" in pyproject()["project"]["scripts"]
    result = subprocess.run(
        [sys.executable, "-m", "pnav", "--help"], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 0 and "usage: pnav" in result.stdout


def test_the_worlds_sit_where_the_sims_default_world_points() -> None:
    instructions = dockerfile_instructions()
    workdirs = [args for keyword, args in instructions if keyword == "WORKDIR"]
    copy_worlds = [args for keyword, args in instructions if keyword == "COPY" and "worlds" in args]
    assert copy_worlds == ["worlds/ worlds/"]
    assert workdirs[-1] == "/app"
    default = interpolate(environment(services()["sim"])["PNAV_SIM_WORLD"])
    assert default == "worlds/warehouse.yaml"
    assert (ROOT / default).is_file()


# -- docker compose itself, when it is here ---------------------------------------------------


def test_docker_compose_config_accepts_the_file() -> None:
    docker = shutil.which("docker")
    if docker is None:
        pytest.skip("no docker client on this machine")
    version = subprocess.run(
        [docker, "compose", "version"], capture_output=True, text=True, timeout=60
    )
    if version.returncode != 0:
        reason = (version.stderr or version.stdout).strip().splitlines()
        pytest.skip(f"the docker client has no compose plugin: {reason[0] if reason else '?'}")
    result = subprocess.run(
        [docker, "compose", "-f", str(COMPOSE_FILE), "config", "--quiet"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )
    assert result.returncode == 0, result.stderr


def test_the_hostname_default_instance_matches_what_the_check_builds() -> None:
    # the check derives <hostname>-$* from socket.gethostname() with dots replaced, as
    # common.config.default_instance does; a change there must be mirrored in the check
    host = socket.gethostname().replace(".", "-")
    assert default_instance() == f"{host}-{os.getpid()}"
    key = zenoh.KeyExpr(keys.alive_key("planner", host + "-$*"))
    assert key.intersects(zenoh.KeyExpr(keys.alive_key("planner", default_instance())))

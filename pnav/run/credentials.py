"""The fleet's credentials: one Postgres password per role, one Zenoh password per service.

The compose file (deploy/docker-compose.yml) has no default for any of them: each is a
variable of the shell or of ``deploy/.env``, and the router's user/password dictionary is a
file the compose file mounts as a secret. ``pnav secrets`` writes both, with random
passwords, readable by their owner only. ``pnav migrate --roles`` (the compose migration job)
reads the Postgres ones to create the roles (common.contract.roles).
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Mapping
from pathlib import Path

from common.errors import ConfigError, UsageError

# The Postgres bootstrap superuser's password (the official image's variable).
SUPERUSER_PASSWORD = "POSTGRES_PASSWORD"
# role (short name) -> the variable holding its Postgres password
DB_PASSWORDS = {
    "bridge": "PNAV_DB_PASSWORD_BRIDGE",
    "strategy": "PNAV_DB_PASSWORD_STRATEGY",
    "planner": "PNAV_DB_PASSWORD_PLANNER",
    "controller": "PNAV_DB_PASSWORD_CONTROLLER",
    "decision": "PNAV_DB_PASSWORD_DECISION",
    "user": "PNAV_DB_PASSWORD_USER",
}
# Zenoh user -> the variable holding its password (the compose file hands it to the
# service's container as PNAV_ZENOH_PASSWORD)
ZENOH_PASSWORDS = {
    "sim": "PNAV_ZENOH_PASSWORD_SIM",
    "bridge": "PNAV_ZENOH_PASSWORD_BRIDGE",
    "strategy": "PNAV_ZENOH_PASSWORD_STRATEGY",
    "planner": "PNAV_ZENOH_PASSWORD_PLANNER",
    "controller": "PNAV_ZENOH_PASSWORD_CONTROLLER",
    "decision": "PNAV_ZENOH_PASSWORD_DECISION",
    "user": "PNAV_ZENOH_PASSWORD_USER",
    # strategy, planner, controller and decision in one host process
    # (deploy/docker-compose.composed.yml; common.contract.acl.DEFAULT_HOSTS)
    "host-strategy-planner-controller-decision": "PNAV_ZENOH_PASSWORD_HOST",
}
# The path of the router's dictionary (one user:password a line), for the compose secret.
ZENOH_USERS_FILE = "PNAV_ZENOH_USERS_FILE"
USERS_FILE_NAME = "zenoh-users.txt"
ENV_FILE_NAME = ".env"


def db_passwords_from_env(env: Mapping[str, str] | None = None) -> dict[str, str]:
    """Each role's password from its variable; every one is required."""
    env = os.environ if env is None else env
    missing = [var for var in DB_PASSWORDS.values() if not env.get(var, "")]
    if missing:
        raise ConfigError(
            f"{', '.join(missing)} not set: every role needs its password "
            "(`pnav secrets` writes them to deploy/.env)"
        )
    return {role: env[var] for role, var in DB_PASSWORDS.items()}


def _password() -> str:
    # hex: safe unquoted in a .env file, a DSN and the router's dictionary
    return secrets.token_hex(24)


def generate(directory: Path, *, force: bool = False) -> tuple[Path, Path]:
    """Write ``directory/.env`` and ``directory/zenoh-users.txt`` with fresh passwords;
    return their paths. Refuses to overwrite either unless ``force``."""
    env_file = directory / ENV_FILE_NAME
    users_file = directory / USERS_FILE_NAME
    if not directory.is_dir():
        raise UsageError(f"{directory} is not a directory")
    for path in (env_file, users_file):
        if path.exists() and not force:
            raise UsageError(f"{path} exists: keep it, or pass --force to replace it")
    db = {var: _password() for var in (SUPERUSER_PASSWORD, *DB_PASSWORDS.values())}
    zenoh = {user: _password() for user in ZENOH_PASSWORDS}
    lines = [
        "# written by `pnav secrets`: the fleet's passwords (docs/DEPLOY.md, Least privilege)",
        *(f"{var}={value}" for var, value in db.items()),
        *(f"{ZENOH_PASSWORDS[user]}={value}" for user, value in zenoh.items()),
        f"{ZENOH_USERS_FILE}=./{USERS_FILE_NAME}",
    ]
    _write_private(env_file, "\n".join(lines) + "\n")
    _write_private(users_file, "".join(f"{user}:{pw}\n" for user, pw in zenoh.items()))
    return env_file, users_file


def _write_private(path: Path, text: str) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as out:
        out.write(text)
    path.chmod(0o600)

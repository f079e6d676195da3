"""Where a running ``pnav up`` says how to reach it, so commands in other terminals can.

The file lives at ``$PNAV_STATE_DIR/stack.json`` (default ``$XDG_STATE_HOME/pnav`` or
``~/.local/state/pnav``). Environment variables win over it: with ``PNAV_DATABASE_URL`` and
``PNAV_ZENOH_CONNECT`` set, commands talk to that stack (a compose fleet, say) instead.
"""

from __future__ import annotations

import contextlib
import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

from common.config import ZenohSettings
from common.contract.grants import USER
from common.errors import UsageError
from common.postmaster import alive


def state_dir() -> Path:
    explicit = os.environ.get("PNAV_STATE_DIR")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "pnav"


def stack_file() -> Path:
    return state_dir() / "stack.json"


@dataclass(frozen=True)
class StackInfo:
    pid: int
    database_url: str
    zenoh_connect: str
    world: str
    rate: str
    log_dir: str
    # the embedded Postgres's data directory ("" for a server of PNAV_DATABASE_URL), and
    # whether it is a temporary one: what a later `pnav up` cleans if this stack died
    postgres_dir: str = ""
    postgres_temporary: bool = False
    # each role's DSN (common.contract.roles): a service started by hand next to the stack
    # connects as its own role, `url_for("controller")`; database_url is people's (pnav_user)
    role_urls: dict[str, str] = field(default_factory=dict)
    # each bus identity's Zenoh password for this run (pnav.run.local_stack.BusCredentials); the
    # router refuses a session without one
    zenoh_passwords: dict[str, str] = field(default_factory=dict)

    def zenoh(self, identity: str = USER) -> ZenohSettings:
        """A client of the stack's router, authenticated as ``identity`` (default: people)."""
        password = self.zenoh_passwords.get(identity)
        if self.zenoh_passwords and password is None:
            known = ", ".join(sorted(self.zenoh_passwords))
            raise UsageError(f"no Zenoh identity {identity!r} in this stack (known: {known})")
        return ZenohSettings(
            mode="client",
            connect=(self.zenoh_connect,),
            user=identity if password else None,
            password=password,
        )

    def env_for(self, identity: str) -> dict[str, str]:
        """The variables a process started by hand needs to join this stack as ``identity``
        (a service's name, or ``user``): its database role and its Zenoh user."""
        if self.role_urls and identity not in self.role_urls:
            known = ", ".join(sorted(self.role_urls))
            raise UsageError(f"no role {identity!r} in this stack (known: {known})")
        return {"PNAV_DATABASE_URL": self.url_for(identity), **self.zenoh(identity).to_env()}

    def url_for(self, role: str) -> str:
        """The DSN of ``role`` (a service's name, or ``user``)."""
        return self.role_urls.get(role, self.database_url)


def write(info: StackInfo) -> None:
    path = stack_file()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.touch(mode=0o600)  # it holds the roles' passwords of this run
    tmp.chmod(0o600)
    tmp.write_text(json.dumps(asdict(info), indent=2))
    tmp.replace(path)


def remove(pid: int) -> None:
    """Remove the file if it still describes the stack of ``pid``."""
    info = read()
    if info is not None and info.pid == pid:
        with contextlib.suppress(FileNotFoundError):
            stack_file().unlink()


def _load() -> StackInfo | None:
    try:
        data = json.loads(stack_file().read_text())
        return StackInfo(**data)
    except (FileNotFoundError, json.JSONDecodeError, TypeError):
        return None


def read() -> StackInfo | None:
    """The running stack, or None (no file, or its launcher is gone)."""
    info = _load()
    return info if info is not None and alive(info.pid) else None


def leftover() -> StackInfo | None:
    """The file of a stack whose launcher died without removing it, or None."""
    info = _load()
    return info if info is not None and not alive(info.pid) else None


def forget(info: StackInfo) -> None:
    """Remove the file of a dead stack (after cleaning what it left)."""
    current = _load()
    if current is not None and current.pid == info.pid:
        with contextlib.suppress(FileNotFoundError):
            stack_file().unlink()


def connection() -> tuple[str, ZenohSettings]:
    """Database URL and Zenoh settings of the stack to talk to; UsageError if there is none."""
    url = os.environ.get("PNAV_DATABASE_URL", "").strip()
    if url:
        return url, ZenohSettings.from_env()
    info = read()
    if info is None:
        raise UsageError(
            "no running stack: start one with `pnav up` (or set PNAV_DATABASE_URL and "
            "PNAV_ZENOH_CONNECT to reach another one)"
        )
    return info.database_url, info.zenoh()

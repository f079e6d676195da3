"""Real infrastructure for tests and benchmarks: embedded Postgres and loopback Zenoh.

Nothing here is mocked. :class:`EmbeddedPostgres` runs a real Postgres (the ``pgserver``
package) in a private directory; :func:`free_port` picks loopback ports so parallel runs do
not collide; :func:`loopback_zenoh` runs an in-process router with multicast scouting off.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import tempfile
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from common.config import ZenohSettings


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


@contextlib.contextmanager
def loopback_zenoh() -> Iterator[ZenohSettings]:
    """Run a Zenoh router on a free loopback port; yield the settings clients use."""
    from common.bus import start_router

    last_error: Exception | None = None
    for _ in range(5):
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        try:
            router = start_router((endpoint,))
        except Exception as exc:  # the port was taken in between: pick another
            last_error = exc
            continue
        try:
            yield ZenohSettings(mode="client", connect=(endpoint,))
        finally:
            router.close()
        return
    raise RuntimeError(f"could not start a loopback Zenoh router: {last_error}")


class EmbeddedPostgres:
    """A real Postgres server in a private directory, started with ``pgserver``."""

    def __init__(self, data_dir: str | Path | None = None, *, persistent: bool = False) -> None:
        self._owns_dir = data_dir is None
        self.data_dir = Path(data_dir or tempfile.mkdtemp(prefix="pnav-pg-"))
        self.persistent = persistent
        self._server: Any = None

    def start(self) -> str:
        """Start (or attach to) the server; return its admin DSN."""
        # pgserver wants a runtime dir at import time; CI machines may not set one.
        if not os.environ.get("XDG_RUNTIME_DIR"):
            os.environ["XDG_RUNTIME_DIR"] = tempfile.mkdtemp(prefix="pnav-run-")
        import pgserver

        self._server = pgserver.get_server(  # type: ignore[attr-defined]
            self.data_dir, cleanup_mode=None if self.persistent else "stop"
        )
        uri: str = self._server.get_uri()
        return uri

    def dsn(self, database: str = "postgres") -> str:
        uri: str = self._server.get_uri(database)
        return uri

    def create_database(self, name: str | None = None, template: str | None = None) -> str:
        """Create a database (optionally from ``template``); return its DSN."""
        name = name or f"t_{uuid.uuid4().hex[:12]}"
        tmpl = f" TEMPLATE {template}" if template else ""
        self._server.psql(f"CREATE DATABASE {name}{tmpl};")
        return self.dsn(name)

    def stop(self) -> None:
        if self._server is not None:
            with contextlib.suppress(Exception):
                self._server.cleanup()
            self._server = None
        if self._owns_dir and not self.persistent:
            # the postmaster may take a moment to release its files
            for _ in range(10):
                try:
                    shutil.rmtree(self.data_dir)
                    break
                except OSError:
                    time.sleep(0.1)

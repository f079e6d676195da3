"""An embedded Postgres and free loopback ports: what a local stack (``pnav up``), the tests
and the benchmarks run on.

Nothing here is mocked. :class:`EmbeddedPostgres` runs a real Postgres (the ``pgserver``
package) in a private directory; :func:`free_port` picks loopback ports so parallel runs do
not collide.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import tempfile
import time
import uuid
from pathlib import Path
from typing import Any


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


# A cluster made for one run and removed after it does not fsync. fsync protects a commit
# against the *machine* losing power, after which such a cluster is of no use to anyone; a
# crash of Postgres itself loses no committed row without it, because a commit still hands
# its WAL to the operating system before it returns (synchronous_commit stays on: the
# contract's "no committed row lost", checked by tests/unit/test_embedded_postgres.py). It
# takes the fdatasync (0.75 ms p50 on this project's machine, tens of ms in its tail) off
# every synchronous commit, two per sense-to-act sample (docs/BENCHMARKS.md). A cluster in
# a directory the caller chose (`pnav up --data-dir`) and any PNAV_DATABASE_URL keep fsync.
_THROWAWAY_SETTINGS = "ALTER SYSTEM SET fsync = off;\nSELECT pg_reload_conf();\n"


class EmbeddedPostgres:
    """A real Postgres server in a private directory, started with ``pgserver``. A
    temporary one (no ``data_dir`` given) runs without fsync (see _THROWAWAY_SETTINGS)."""

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
        if self.temporary:
            self._server.psql(_THROWAWAY_SETTINGS)
        uri: str = self._server.get_uri()
        return uri

    def setting(self, name: str) -> str:
        """A server setting as ``SHOW`` gives it (e.g. ``fsync``)."""
        out: str = self._server.psql(f"SHOW {name};")
        lines = [line.strip() for line in out.splitlines() if line.strip()]
        return lines[2]  # header, rule, value

    @property
    def temporary(self) -> bool:
        """Whether :meth:`stop` removes the data directory (it was made for this server)."""
        return self._owns_dir and not self.persistent

    def pid(self) -> int | None:
        """The postmaster's pid (None before :meth:`start`)."""
        if self._server is None:
            return None
        pid: int | None = self._server.get_pid()
        return pid

    def restart(self) -> None:
        """Start the postmaster again on the same data directory (so the same socket and DSN)
        after it died. Blocking: pg_ctl waits for the server to accept connections."""
        from common.postmaster import alive, postmaster_pid

        if self._server is None:
            raise RuntimeError("restart() before start()")
        stale = postmaster_pid(self.data_dir)
        if stale is not None and not alive(stale):
            # postgres takes a not yet reaped (zombie) pid for a live postmaster and refuses
            # to start: its lock files go (the socket's lives where the socket does)
            socket_dir = self._server.get_postmaster_info().socket_dir or self.data_dir
            locks = [self.data_dir / "postmaster.pid", *Path(socket_dir).glob(".s.PGSQL.*.lock")]
            for lock in locks:
                with contextlib.suppress(FileNotFoundError):
                    lock.unlink()
        with self._server._lock:
            self._server.ensure_postgres_running()

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
        if self.temporary:
            # the postmaster may take a moment to release its files
            for _ in range(10):
                try:
                    shutil.rmtree(self.data_dir)
                    break
                except OSError:
                    time.sleep(0.1)

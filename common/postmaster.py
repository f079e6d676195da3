"""The embedded Postgres's postmaster: is it alive, restart it, and never leave it behind.

``pgserver`` starts the postmaster with ``pg_ctl``, which detaches it (its parent is init),
so nothing notices when it dies and nothing stops it when the launcher dies. Here:

- :class:`Keeper` (run by the launcher) polls the postmaster and, when it is gone, starts it
  again on the same data directory: the same socket, so every service's PNAV_DATABASE_URL
  stays valid; with a back-off if it keeps dying.
- :func:`start_lifeline` starts a small watcher process (``python -m common.postmaster``)
  that holds the read end of a pipe from the launcher. When the launcher dies, by any
  signal, SIGKILL included, the kernel closes the pipe; the watcher then stops the
  postmaster (whichever one ``postmaster.pid`` names at that moment, so a restarted one
  too) and removes a temporary data directory. A kept ``--data-dir`` is never removed.
- :func:`seed_from_template` fills a new temporary data directory with a copy of a cluster
  that ``initdb`` made once (per machine, user and Postgres build) instead of running
  ``initdb`` for every stack: 0.7 s of a 2 s start-up (docs/BENCHMARKS.md, "Start-up:
  where the seconds and megabytes went"). The copy is the cluster ``initdb`` would make
  (same build, same options); its passwords, settings and schema are set after it starts,
  as before. ``PNAV_PG_TEMPLATE=0`` runs ``initdb`` every time.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import logging
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import IO, Protocol

logger = logging.getLogger("pnav.postgres")

_POLL_S = 0.5
_BACKOFF_FIRST_S = 0.5
_BACKOFF_MAX_S = 10.0
_HEALTHY_AFTER_S = 30.0  # a postmaster that ran this long resets the back-off


def postmaster_pid(data_dir: Path) -> int | None:
    """The pid ``postmaster.pid`` names, or None (no file, or unreadable)."""
    try:
        first = (data_dir / "postmaster.pid").read_text().split("\n", 1)[0]
        return int(first)
    except (OSError, ValueError):
        return None


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, left by an init that does not reap, counts as dead)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            state = stat.read().rsplit(")", 1)[1].split()[0]
        return state not in ("Z", "X")
    except (OSError, IndexError):
        pass
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def kill_postmaster(data_dir: Path, wait_s: float = 5.0) -> None:
    """Stop the postmaster of ``data_dir`` at once (SIGQUIT: immediate shutdown, then
    SIGKILL), if one runs; wait for it to go."""
    pid = postmaster_pid(data_dir)
    if pid is None or not alive(pid) or not _serves(pid, data_dir):
        return
    for sig in (signal.SIGQUIT, signal.SIGKILL):
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, sig)
        deadline = time.monotonic() + wait_s / 2
        while alive(pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        if not alive(pid):
            return


def _serves(pid: int, data_dir: Path) -> bool:
    """Whether ``pid`` is a postgres of ``data_dir`` (a stale postmaster.pid may name a pid
    since reused by another process); True where /proc cannot tell."""
    try:
        cmdline = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return True
    return b"postgres" in cmdline and str(data_dir).encode() in cmdline


def clean_up(data_dir: Path, *, remove: bool) -> None:
    """Stop the postmaster of ``data_dir`` if one runs; remove the directory if ``remove``."""
    kill_postmaster(data_dir)
    if not remove:
        return
    for _ in range(20):  # the postmaster's children may hold files a moment longer
        try:
            shutil.rmtree(data_dir)
            return
        except FileNotFoundError:
            return
        except OSError:
            time.sleep(0.1)


class Restartable(Protocol):
    data_dir: Path

    def pid(self) -> int | None: ...

    def restart(self) -> None: ...


class Keeper:
    """Restart the embedded postmaster whenever it dies, until stopped."""

    def __init__(self, postgres: Restartable) -> None:
        self.postgres = postgres
        self.restarts = 0
        self._backoff = _BACKOFF_FIRST_S
        self._started = time.monotonic()

    async def run(self, stop: asyncio.Event) -> None:
        while not stop.is_set():
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), _POLL_S)
            if stop.is_set():
                return
            pid = self.postgres.pid()
            if pid is not None and alive(pid):
                continue
            await self._restart(postmaster_pid(self.postgres.data_dir) or pid, stop)

    async def _restart(self, pid: int | None, stop: asyncio.Event) -> None:
        ran_for = time.monotonic() - self._started
        if ran_for > _HEALTHY_AFTER_S:
            self._backoff = _BACKOFF_FIRST_S
        self.restarts += 1
        logger.warning(
            "embedded Postgres (pid %s) died after %.1f s; restarting it on %s in %.1f s "
            "(restart %d)",
            pid,
            ran_for,
            self.postgres.data_dir,
            self._backoff,
            self.restarts,
        )
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), self._backoff)
        if stop.is_set():
            return
        self._backoff = min(self._backoff * 2, _BACKOFF_MAX_S)
        started = time.monotonic()
        quiet = logging.getLogger("pgserver")
        level = quiet.level
        quiet.setLevel(logging.CRITICAL)  # it prints the whole server log on each failure
        try:
            await asyncio.to_thread(self.postgres.restart)
        except Exception as exc:
            # counted as a death: the next poll tries again, later
            logger.warning(
                "embedded Postgres did not restart: %s; its log ends: %s",
                type(exc).__name__,
                _log_tail(self.postgres.data_dir),
            )
            self._started = time.monotonic()
            return
        finally:
            quiet.setLevel(level)
        self._started = time.monotonic()
        logger.info(
            "embedded Postgres restarted (pid %s) in %.1f s (restart %d)",
            self.postgres.pid(),
            self._started - started,
            self.restarts,
        )


def _log_tail(data_dir: Path, lines: int = 2) -> str:
    try:
        tail = (data_dir / "log").read_text(errors="replace").splitlines()[-lines:]
    except OSError:
        return "-"
    return " | ".join(line.strip() for line in tail)


# -- the template cluster ------------------------------------------------------------------


def template_dir(variant: str = "") -> Path | None:
    """Where this user's template cluster for this Postgres build lives (under
    ``$XDG_CACHE_HOME/pnav``, else ``~/.cache/pnav``), or None when ``PNAV_PG_TEMPLATE=0``
    or pgserver is not installed. Its name changes with the build (the ``postgres`` binary's
    path, size and time), so a new pgserver never copies an old build's cluster, and with
    ``variant`` (what the caller put in it: the contract's migrations, common.stack)."""
    if os.environ.get("PNAV_PG_TEMPLATE", "").strip().lower() in ("0", "false", "no", "off"):
        return None
    # pgserver wants a runtime dir at import time (as common.testing.EmbeddedPostgres.start)
    if not os.environ.get("XDG_RUNTIME_DIR"):
        os.environ["XDG_RUNTIME_DIR"] = tempfile.mkdtemp(prefix="pnav-run-")
    try:
        from pgserver._commands import POSTGRES_BIN_PATH
    except ImportError:
        return None
    try:
        binary = (POSTGRES_BIN_PATH / "postgres").stat()
    except OSError:
        return None
    build = f"{POSTGRES_BIN_PATH}:{binary.st_size}:{binary.st_mtime_ns}:{os.getuid()}:{variant}"
    cache = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(cache) / "pnav" / f"pg-template-{hashlib.sha256(build.encode()).hexdigest()[:16]}"


def _make_template(target: Path, prepare: Callable[[str], None] | None) -> None:
    """initdb a cluster the way pgserver does (it starts the server on it once; stopped
    cleanly, it is a cluster at rest) and ``prepare(dsn)`` it while it runs. It is made in
    a short temporary path (pgserver puts the socket in the data directory only if its
    path is short, else in a directory every pgserver on the machine shares, on the same
    port), then moved beside ``target`` and renamed into place, so that two stacks
    starting together never copy a half-made one."""
    import pgserver

    target.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    making = Path(tempfile.mkdtemp(prefix="pnav-pgt-"))
    staging = Path(tempfile.mkdtemp(prefix=f"{target.name}.", dir=target.parent))
    try:
        server = pgserver.get_server(making, cleanup_mode="stop")  # type: ignore[attr-defined]
        try:
            if prepare is not None:
                prepare(server.get_uri())
        finally:
            server.cleanup()
        for leftover in ("log", ".handle_pids.json", "postmaster.pid"):
            with contextlib.suppress(FileNotFoundError):
                (making / leftover).unlink()
        _copy_tree(making, staging)
        try:
            staging.rename(target)
        except OSError:
            if not (target / "PG_VERSION").is_file():  # not another stack's, made meanwhile
                raise
    finally:
        shutil.rmtree(making, ignore_errors=True)
        shutil.rmtree(staging, ignore_errors=True)


def _copy_tree(template: Path, data_dir: Path) -> None:
    """``cp -a`` the template into ``data_dir``, a few parts at once: of a cluster's ~1,000
    files the copy's time is creating them (270 us each on the 2-core CI machine, 0.55 s in
    all), and creating runs in parallel across directories (0.15-0.2 s). ``cp -a`` keeps
    owners and modes: as root, pgserver runs Postgres as its own user, who must own the
    files as initdb left them."""
    base = template / "base"
    databases = sorted(base.iterdir())  # one copy each; the rest of the cluster in one more
    rest = [str(p) for p in template.iterdir() if p != base]
    (data_dir / "base").mkdir()
    for made, like in ((data_dir / "base", base), (data_dir, template)):
        shutil.copystat(like, made)
        info = like.stat()
        os.chown(made, info.st_uid, info.st_gid)
    jobs = [(rest, data_dir)] + [([str(d)], data_dir / "base") for d in databases]
    copies = [
        subprocess.Popen(["cp", "-a", *sources, str(into)], stderr=subprocess.PIPE)
        for sources, into in jobs
    ]
    codes = [copy.wait() for copy in copies]
    for copy, code in zip(copies, codes, strict=True):
        if code != 0:
            raise subprocess.CalledProcessError(code, copy.args)


def seed_from_template(
    data_dir: Path, *, variant: str = "", prepare: Callable[[str], None] | None = None
) -> bool:
    """Copy the template cluster of ``variant`` (made now if there is none: initdb, then
    ``prepare(dsn)`` on it) into the empty ``data_dir``; True if copied. False, and
    ``data_dir`` left empty for pgserver's own initdb, when there is no template to use
    (PNAV_PG_TEMPLATE=0, an unwritable cache, a failed copy)."""
    template = template_dir(variant)
    if template is None or any(data_dir.iterdir()):
        return False
    try:
        if not (template / "PG_VERSION").is_file():
            _make_template(template, prepare)
        _copy_tree(template, data_dir)
    except (OSError, subprocess.CalledProcessError) as exc:
        logger.warning("no template cluster (%s): running initdb", exc)
        for entry in data_dir.iterdir():
            if entry.is_dir():
                shutil.rmtree(entry, ignore_errors=True)
            else:
                entry.unlink(missing_ok=True)
        return False
    return True


# -- the lifeline ---------------------------------------------------------------------------


class Lifeline:
    """The launcher's end of the watcher's pipe (see the module's docstring)."""

    def __init__(self, process: subprocess.Popen[bytes], pipe: IO[bytes]) -> None:
        self.process = process
        self.pipe = pipe

    def close(self, wait_s: float = 10.0) -> None:
        """The launcher has stopped Postgres itself: close the pipe (the watcher checks, finds
        nothing left, exits) and reap the watcher."""
        with contextlib.suppress(OSError):
            self.pipe.close()
        try:
            self.process.wait(wait_s)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()


def start_lifeline(data_dir: Path, *, temporary: bool) -> Lifeline:
    """Start the watcher of ``data_dir`` (call from the main thread, before the postmaster
    starts, so no child of ours inherits the pipe)."""
    argv = [sys.executable, "-m", "common.postmaster", str(data_dir)]
    if temporary:
        argv.append("--remove")
    process = subprocess.Popen(
        argv,
        stdin=subprocess.PIPE,
        start_new_session=True,  # a Ctrl-C in the terminal is the launcher's to handle
        close_fds=True,
    )
    assert process.stdin is not None
    return Lifeline(process, process.stdin)


def watch(data_dir: Path, remove: bool) -> None:
    """The watcher's body: block until the launcher's end of stdin closes, then clean up."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)  # the pipe decides, not a stray signal
    while sys.stdin.buffer.read(4096):
        pass
    clean_up(data_dir, remove=remove)


if __name__ == "__main__":
    watch(Path(sys.argv[1]), "--remove" in sys.argv[2:])

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
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import shutil
import signal
import subprocess
import sys
import time
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

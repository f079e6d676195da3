"""The template cluster: a local stack's temporary Postgres data directory is a copy of a
cluster made once (per machine user, Postgres build and contract version) instead of a new
``initdb`` and every migration for each stack: 0.7 s of initdb and 0.3 s of migrations on a
quiet 2-core machine, 7-8 s on a loaded one (docs/BENCHMARKS.md, "Start-up: where the
seconds and megabytes went").

The copy is the cluster ``initdb`` would make (same build, same options) with what the
caller's ``prepare`` gave it (pnav.run.local_stack: the contract's roles without passwords, its
migrations and grants); each stack then sets its own passwords, settings and grants, as
before. Templates live under ``$XDG_CACHE_HOME/pnav`` (``~/.cache/pnav``);
``PNAV_PG_TEMPLATE=0`` runs ``initdb`` every time.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import shutil
import subprocess
import tempfile
from collections.abc import Callable
from pathlib import Path

logger = logging.getLogger("pnav.postgres")


def template_dir(variant: str = "") -> Path | None:
    """Where this user's template cluster for this Postgres build lives (under
    ``$XDG_CACHE_HOME/pnav``, else ``~/.cache/pnav``), or None when ``PNAV_PG_TEMPLATE=0``
    or pgserver is not installed. Its name changes with the build (the ``postgres`` binary's
    path, size and time), so a new pgserver never copies an old build's cluster, and with
    ``variant`` (what the caller put in it: the contract's migrations, pnav.run.local_stack)."""
    if os.environ.get("PNAV_PG_TEMPLATE", "").strip().lower() in ("0", "false", "no", "off"):
        return None
    # pgserver wants a runtime dir at import time (as EmbeddedPostgres.start does,
    # pnav/run/embedded_postgres.py)
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

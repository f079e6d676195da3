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

The *spare*: copying the template's ~1,100 files is most of a local stack's start (0.6-1.3 s
on a quiet 2-core machine, seconds when its disk is busy), so a stack that took its cluster
from the template leaves, when it stops, a copy ready beside the template for the next
one (:func:`leave_spare`); the next stack takes it by renaming (:func:`seed_from_template`),
one stack only, as a rename is atomic. The copy is made when the server has stopped, off
any start's path; a stack killed before its stop leaves none, and the next start copies as
before. Each template's spare is at most one directory (40 MB). ``PNAV_PG_SPARE=0`` makes
and takes none. Templates (and their spares) unused for :data:`UNUSED_DAYS` are removed when
a new template is made.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import shutil
import subprocess
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Final, Literal

logger = logging.getLogger("pnav.postgres")

# A template (with its spare) nobody has copied for this long is some old build's or
# contract's: removed when a new template is made.
UNUSED_DAYS: Final = 14
# A spare's staging directory older than this was left by a copy that was killed.
STALE_STAGING_S: Final = 600.0

Seeded = Literal["spare", "copy"]  # how a data directory got its cluster


def template_dir(variant: str = "") -> Path | None:
    """Where this user's template cluster for this Postgres build lives (under
    ``$XDG_CACHE_HOME/pnav``, else ``~/.cache/pnav``), or None when ``PNAV_PG_TEMPLATE=0``
    or pgserver is not installed. Its name changes with the build (the ``postgres`` binary's
    path, size and time), so a new pgserver never copies an old build's cluster, and with
    ``variant`` (what the caller put in it: the contract's migrations, pnav.run.local_stack)."""
    if _switched_off("PNAV_PG_TEMPLATE"):
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


def _switched_off(name: str) -> bool:
    return os.environ.get(name, "").strip().lower() in ("0", "false", "no", "off")


def _spare(template: Path) -> Path:
    return template.with_name(f"{template.name}.spare")


def _prune(keep: Path) -> None:
    """Remove the templates (and spares) beside ``keep`` that nobody copied for
    :data:`UNUSED_DAYS` (a template's time is refreshed each time it is used)."""
    old = time.time() - UNUSED_DAYS * 86400
    for other in keep.parent.glob("pg-template-*"):
        if other.name.split(".")[0] == keep.name:
            continue
        try:
            unused = other.stat().st_mtime < old
        except OSError:
            continue
        if unused:
            logger.info("removing an unused template cluster: %s", other)
            shutil.rmtree(other, ignore_errors=True)


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
    _prune(target)


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


def _empty(data_dir: Path) -> None:
    for entry in data_dir.iterdir():
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            entry.unlink(missing_ok=True)


def _take_spare(template: Path, data_dir: Path) -> bool:
    """Move the template's spare into the empty ``data_dir``; False if there is none (or
    it cannot be moved there: another file system), ``data_dir`` then left empty."""
    claimed = template.with_name(f"{template.name}.taken-{os.getpid()}-{time.monotonic_ns()}")
    try:
        _spare(template).rename(claimed)  # atomic: of two stacks starting, one gets it
    except OSError:
        return False
    try:
        for entry in claimed.iterdir():
            entry.rename(data_dir / entry.name)
        shutil.copystat(claimed, data_dir)
        info = claimed.stat()
        os.chown(data_dir, info.st_uid, info.st_gid)
    except OSError as exc:
        logger.info("the spare cluster could not be used (%s): copying the template", exc)
        _empty(data_dir)
        return False
    finally:
        shutil.rmtree(claimed, ignore_errors=True)
    return True


def seed_from_template(
    data_dir: Path, *, variant: str = "", prepare: Callable[[str], None] | None = None
) -> Seeded | None:
    """Give the empty ``data_dir`` the template cluster of ``variant`` (made now if there is
    none: initdb, then ``prepare(dsn)`` on it): its spare if one is ready (``"spare"``),
    else a copy (``"copy"``). None, and ``data_dir`` left empty for pgserver's own initdb,
    when there is no template to use (PNAV_PG_TEMPLATE=0, an unwritable cache, a failed
    copy)."""
    template = template_dir(variant)
    if template is None or any(data_dir.iterdir()):
        return None
    try:
        if not (template / "PG_VERSION").is_file():
            _make_template(template, prepare)
        os.utime(template)  # used: not pruned (see _prune)
        if not _switched_off("PNAV_PG_SPARE") and _take_spare(template, data_dir):
            return "spare"
        _copy_tree(template, data_dir)
    except (OSError, subprocess.CalledProcessError) as exc:
        logger.warning("no template cluster (%s): running initdb", exc)
        _empty(data_dir)
        return None
    return "copy"


def leave_spare(variant: str = "") -> bool:
    """Copy the template of ``variant`` to its spare if it has none (a stack that took its
    cluster from the template calls this once its server has stopped: the copy is then off
    every start's path); True if a spare was made. Two stacks stopping together make one:
    the copy is staged under a name of its own and renamed into place."""
    template = template_dir(variant)
    if template is None or _switched_off("PNAV_PG_SPARE"):
        return False
    spare = _spare(template)
    if spare.exists() or not (template / "PG_VERSION").is_file():
        return False
    if os.stat(template.parent).st_dev != os.stat(tempfile.gettempdir()).st_dev:
        return False  # a stack's directory is elsewhere: a spare could not be moved there
    for stale in template.parent.glob(f"{template.name}.staging-*"):
        with contextlib.suppress(OSError):
            if time.time() - stale.stat().st_mtime > STALE_STAGING_S:
                shutil.rmtree(stale, ignore_errors=True)
    staging = Path(tempfile.mkdtemp(prefix=f"{template.name}.staging-", dir=template.parent))
    try:
        _copy_tree(template, staging)
        staging.rename(spare)
    except (OSError, subprocess.CalledProcessError) as exc:
        if not spare.exists():  # not another stack's, made meanwhile
            logger.info("no spare cluster left (%s)", exc)
        return False
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return True

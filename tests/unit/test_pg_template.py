"""A local stack's temporary cluster is a copy of a template cluster initdb made once: the
copy is the template file for file, and a server starts on it and serves; with
PNAV_PG_TEMPLATE=0, or a cluster already in the directory, nothing is copied. A stack that
stops leaves the next one a spare copy, which one stack takes whole."""

from __future__ import annotations

import filecmp
import os
import time
from pathlib import Path

import asyncpg
import pytest

from common.pgtemplate import UNUSED_DAYS, leave_spare, seed_from_template, template_dir
from pnav.run.embedded_postgres import EmbeddedPostgres

pytestmark = pytest.mark.timeout(120)


def same_tree(a: Path, b: Path) -> bool:
    cmp = filecmp.dircmp(a, b)
    if cmp.left_only or cmp.right_only or cmp.diff_files or cmp.funny_files:
        return False
    return all(same_tree(a / d, b / d) for d in cmp.common_dirs)


async def databases_served(data_dir: Path) -> int:
    """How many databases a server started on ``data_dir`` serves (then stopped)."""
    server = EmbeddedPostgres(data_dir)
    server.start()
    try:
        conn = await asyncpg.connect(server.dsn())
        try:
            count: int = await conn.fetchval("SELECT count(*) FROM pg_database")
            return count
        finally:
            await conn.close()
    finally:
        server.stop()


async def test_a_seeded_directory_is_the_template_and_serves(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv("PNAV_PG_TEMPLATE", raising=False)
    monkeypatch.delenv("PNAV_PG_SPARE", raising=False)
    data = tmp_path / "data"
    data.mkdir(mode=0o700)
    assert seed_from_template(data) == "copy"  # the template is made now, then copied
    template = template_dir()
    assert template is not None and template.is_relative_to(tmp_path / "cache")
    assert (data / "PG_VERSION").is_file()
    assert same_tree(template, data)
    assert not seed_from_template(data)  # a cluster is there already: left alone
    assert await databases_served(data) == 3


def test_no_template_when_switched_off(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setenv("PNAV_PG_TEMPLATE", "0")
    data = tmp_path / "data"
    data.mkdir()
    assert template_dir() is None
    assert not seed_from_template(data)
    assert not any(data.iterdir())  # pgserver's initdb makes the cluster


def fresh(tmp_path: Path, name: str) -> Path:
    made = tmp_path / name
    made.mkdir(mode=0o700)
    return made


async def test_a_stopped_stack_leaves_a_spare_that_one_next_stack_takes_whole(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setenv("TMPDIR", str(tmp_path))  # the stacks' directories' file system
    monkeypatch.delenv("PNAV_PG_TEMPLATE", raising=False)
    monkeypatch.delenv("PNAV_PG_SPARE", raising=False)
    assert seed_from_template(fresh(tmp_path, "first")) == "copy"  # no spare yet
    template = template_dir()
    assert template is not None
    spare = template.with_name(template.name + ".spare")
    assert leave_spare() and same_tree(template, spare)
    assert not leave_spare()  # one spare at most
    taken = fresh(tmp_path, "second")
    assert seed_from_template(taken) == "spare"
    assert not spare.exists() and same_tree(template, taken)
    assert (taken.stat().st_mode & 0o777) == (template.stat().st_mode & 0o777)
    assert seed_from_template(fresh(tmp_path, "third")) == "copy"  # the spare was taken
    assert [p.name for p in template.parent.iterdir()] == [template.name]  # nothing left
    assert await databases_served(taken) == 3


def test_no_spare_is_made_or_taken_when_switched_off(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.delenv("PNAV_PG_TEMPLATE", raising=False)
    monkeypatch.delenv("PNAV_PG_SPARE", raising=False)
    assert seed_from_template(fresh(tmp_path, "first")) == "copy"
    assert leave_spare()
    monkeypatch.setenv("PNAV_PG_SPARE", "0")
    assert seed_from_template(fresh(tmp_path, "second")) == "copy"  # the spare stays unused
    assert not leave_spare()


def test_a_template_unused_for_long_goes_when_a_new_one_is_made(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    cache = tmp_path / "cache" / "pnav"
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv("PNAV_PG_TEMPLATE", raising=False)
    old, recent = cache / "pg-template-0ld", cache / "pg-template-recent"
    for made in (old, recent, cache / "pg-template-0ld.spare"):
        made.mkdir(parents=True)
    long_ago = time.time() - (UNUSED_DAYS + 1) * 86400
    os.utime(old, (long_ago, long_ago))
    os.utime(cache / "pg-template-0ld.spare", (long_ago, long_ago))
    assert seed_from_template(fresh(tmp_path, "data"), variant="new") == "copy"
    template = template_dir("new")
    assert template is not None
    assert sorted(p.name for p in cache.iterdir()) == sorted([template.name, recent.name])

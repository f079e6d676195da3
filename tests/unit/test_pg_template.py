"""A local stack's temporary cluster is a copy of a template cluster initdb made once: the
copy is the template file for file, and a server starts on it and serves; with
PNAV_PG_TEMPLATE=0, or a cluster already in the directory, nothing is copied."""

from __future__ import annotations

import filecmp
from pathlib import Path

import asyncpg
import pytest

from common.pgtemplate import seed_from_template, template_dir
from pnav.run.embedded_postgres import EmbeddedPostgres

pytestmark = pytest.mark.timeout(120)


def same_tree(a: Path, b: Path) -> bool:
    cmp = filecmp.dircmp(a, b)
    if cmp.left_only or cmp.right_only or cmp.diff_files or cmp.funny_files:
        return False
    return all(same_tree(a / d, b / d) for d in cmp.common_dirs)


async def test_a_seeded_directory_is_the_template_and_serves(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv("PNAV_PG_TEMPLATE", raising=False)
    data = tmp_path / "data"
    data.mkdir(mode=0o700)
    assert seed_from_template(data)  # the template is made now, then copied
    template = template_dir()
    assert template is not None and template.is_relative_to(tmp_path / "cache")
    assert (data / "PG_VERSION").is_file()
    assert same_tree(template, data)
    assert not seed_from_template(data)  # a cluster is there already: left alone
    server = EmbeddedPostgres(data)
    server.start()
    try:
        conn = await asyncpg.connect(server.dsn())
        try:
            assert await conn.fetchval("SELECT count(*) FROM pg_database") == 3
        finally:
            await conn.close()
    finally:
        server.stop()


def test_no_template_when_switched_off(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setenv("PNAV_PG_TEMPLATE", "0")
    data = tmp_path / "data"
    data.mkdir()
    assert template_dir() is None
    assert not seed_from_template(data)
    assert not any(data.iterdir())  # pgserver's initdb makes the cluster

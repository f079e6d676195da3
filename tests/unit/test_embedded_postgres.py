"""The embedded Postgres a run makes for itself skips fsync, and still loses no committed row
when Postgres crashes; a cluster in a directory the caller chose keeps fsync."""

from __future__ import annotations

import time
from pathlib import Path

import asyncpg
import pytest

from common.postmaster import kill_postmaster
from pnav.run.embedded_postgres import EmbeddedPostgres

pytestmark = pytest.mark.timeout(120)

ROWS = 300


def settled(server: EmbeddedPostgres, name: str, want: str, within_s: float = 10.0) -> str:
    """The setting once it reads ``want`` (a reload is asynchronous), or its last value."""
    deadline = time.monotonic() + within_s
    value = server.setting(name)
    while value != want and time.monotonic() < deadline:
        time.sleep(0.05)
        value = server.setting(name)
    return value


def test_a_cluster_made_for_the_run_does_not_fsync(pg: EmbeddedPostgres) -> None:
    assert pg.temporary  # the test session's own server, made as `pnav up` makes one
    assert settled(pg, "fsync", "off") == "off"
    assert pg.setting("synchronous_commit") == "on"  # a commit still waits for its WAL


def test_a_cluster_in_a_chosen_directory_keeps_fsync(tmp_path: Path) -> None:
    server = EmbeddedPostgres(tmp_path / "pgdata")
    server.start()
    try:
        assert not server.temporary
        assert server.setting("fsync") == "on"
    finally:
        server.stop()


async def test_every_committed_row_survives_a_postgres_crash_without_fsync() -> None:
    throwaway = EmbeddedPostgres()  # its own: the test kills it
    throwaway.start()
    try:
        await _commit_crash_and_count(throwaway)
    finally:
        throwaway.stop()


async def _commit_crash_and_count(throwaway: EmbeddedPostgres) -> None:
    assert settled(throwaway, "fsync", "off") == "off"
    url = throwaway.dsn()
    conn = await asyncpg.connect(url)
    try:
        await conn.execute("CREATE TABLE written (id int PRIMARY KEY)")
        for i in range(ROWS):  # one commit each, the last a moment before the crash
            await conn.execute("INSERT INTO written VALUES ($1)", i)
    finally:
        await conn.close()

    kill_postmaster(throwaway.data_dir)  # immediate shutdown: no checkpoint, WAL replayed
    throwaway.restart()

    conn = await asyncpg.connect(url)
    try:
        assert await conn.fetchval("SELECT count(*) FROM written") == ROWS
    finally:
        await conn.close()

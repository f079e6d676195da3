"""A database outage in one process: back off, one WARNING, a summary now and then, one INFO."""

from __future__ import annotations

import logging
import sys

import asyncpg
import pytest

from common.db import create_pool
from common.errors import ConnectionFailure
from common.outage import FoldingFilter, Outage, is_connection_error, outage_for


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def lines(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == "pnav.db"]


def test_connection_errors_are_told_from_other_errors() -> None:
    assert is_connection_error(ConnectionRefusedError(111, "refused"))
    assert is_connection_error(asyncpg.ConnectionDoesNotExistError("closed"))
    # the server ended an idle connection; asyncpg notices on the next query (asyncpg#1069)
    assert is_connection_error(
        asyncpg.InternalClientError(
            "cannot switch to state 15; another operation (2) is in progress"
        )
    )
    wrapped = ConnectionFailure("cannot open the lease connection")
    wrapped.__cause__ = ConnectionRefusedError(111, "refused")
    assert is_connection_error(wrapped)
    # a misconfiguration is not an outage
    assert not is_connection_error(ConnectionFailure("no such database"))
    assert not is_connection_error(ValueError("bad row"))


def test_one_warning_a_summary_per_window_and_one_info(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO)
    clock = Clock()
    outage = Outage(window_s=5.0, clock=clock)
    assert outage.may_try() and not outage.down
    outage.failed(ConnectionRefusedError(111, "refused"))
    assert outage.down
    # while down, attempts are refused at once until a probe is due; probes back off
    probes = 0
    for _ in range(200):  # 20 s of attempts every 0.1 s
        clock.now += 0.1
        if outage.may_try():
            probes += 1
            outage.failed(ConnectionRefusedError(111, "refused"))
    assert 10 <= probes <= 16  # 0.2, 0.4, ... then one every 2 s
    said = lines(caplog)
    assert said[0].startswith("database unreachable")
    assert 3 <= sum("still unreachable" in s for s in said) <= 4  # one per 5 s
    outage.recovered()
    assert not outage.down and outage.may_try()
    assert lines(caplog)[-1].startswith("database back after 20.0 s")
    outage.recovered()  # nothing more to say
    assert len(lines(caplog)) == len(said) + 1


def test_the_filter_folds_connection_errors_only_while_down() -> None:
    clock = Clock()
    outage = Outage(clock=clock)
    folding = FoldingFilter([outage])
    other = logging.getLogger("some.service")

    def record(exc: BaseException, level: int = logging.WARNING) -> logging.LogRecord:
        return other.makeRecord(other.name, level, __file__, 1, "failed: %r", (exc,), None)

    refused = ConnectionRefusedError(111, "refused")
    assert folding.filter(record(refused))  # up: every line passes
    outage.failed(refused)
    assert not folding.filter(record(refused))  # down: folded, and counted
    assert folding.filter(record(ValueError("a bug")))  # anything else still passes
    assert folding.filter(record(refused, logging.INFO))
    assert outage.folded == 1


async def test_the_pool_backs_off_while_the_server_is_gone_and_comes_back(db_url: str) -> None:
    pool = await create_pool(db_url, min_size=0, max_size=2)
    outage = outage_for(db_url)
    try:
        assert await pool.fetchval("SELECT 1") == 1
        # the server "goes away": this process cannot connect (as when it is down)
        outage.failed(ConnectionRefusedError(111, "refused"))
        await pool.expire_connections()
        with pytest.raises(ConnectionFailure):
            await pool.fetchval("SELECT 1")  # refused at once: no probe due yet
        # a probe is let through after the back-off, connects, and the outage is over
        outage._next_probe = 0.0
        assert await pool.fetchval("SELECT 1") == 1
        assert not outage.down
    finally:
        outage.recovered()
        await pool.close()


def test_a_lost_connection_is_one_line_not_a_traceback() -> None:
    folding = FoldingFilter([Outage(clock=Clock())])
    other = logging.getLogger("some.service")
    try:
        raise asyncpg.ConnectionDoesNotExistError("connection was closed")
    except asyncpg.ConnectionDoesNotExistError:
        lost = other.makeRecord(other.name, logging.ERROR, __file__, 1, "x", (), sys.exc_info())
    assert folding.filter(lost) and lost.exc_info is None
    assert "connection was closed" in lost.__dict__["error"]
    try:
        raise ValueError("a bug")
    except ValueError:
        bug = other.makeRecord(other.name, logging.ERROR, __file__, 1, "x", (), sys.exc_info())
    assert folding.filter(bug) and bug.exc_info is not None  # a bug keeps its traceback

"""A service asked to stop gets a time limit to drain, then its process leaves anyway: a
bridge whose launcher was killed while it still waited for Postgres (stopped by the
launcher's lifeline) stayed alive for ever, holding the launcher's output open."""

from __future__ import annotations

import asyncio

import pytest

from common.errors import ConnectionFailure, UsageError
from common.runtime import run_stoppable, until_stopped


class Left(Exception):
    pass


def leave(code: int) -> None:
    raise Left(code)


async def test_a_service_that_ignores_its_stop_leaves_after_the_limit(
    caplog: pytest.LogCaptureFixture,
) -> None:
    stop = asyncio.Event()
    never = asyncio.get_running_loop().create_future()  # a start waiting on a dead database
    loop = asyncio.get_running_loop()
    loop.call_later(0.05, stop.set)
    with pytest.raises(Left) as left:
        await until_stopped(never, stop, 0.2, leave)
    assert left.value.args == (1,)
    assert "did not stop within 0.2 s of being asked to; leaving" in caplog.text


async def test_a_service_that_drains_in_time_returns_as_before() -> None:
    stop = asyncio.Event()
    drained: list[str] = []

    async def service() -> None:
        await stop.wait()
        await asyncio.sleep(0.05)  # its drain
        drained.append("yes")

    asyncio.get_running_loop().call_later(0.05, stop.set)
    await until_stopped(service(), stop, 5.0, leave)
    assert drained == ["yes"]


async def test_a_service_that_ends_by_itself_needs_no_stop() -> None:
    async def service() -> None:
        await asyncio.sleep(0.01)

    await until_stopped(service(), asyncio.Event(), 5.0, leave)


async def test_an_error_in_the_service_reaches_the_caller() -> None:
    async def service() -> None:
        raise RuntimeError("broken")

    with pytest.raises(RuntimeError, match="broken"):
        await until_stopped(service(), asyncio.Event(), 5.0, leave)


def test_a_service_or_a_host_gets_its_exit_code_from_how_its_work_ended() -> None:
    # run_service and the host of several services both run their work through this
    async def returns(stop: asyncio.Event) -> str:
        return "done"

    async def misused(stop: asyncio.Event) -> str:
        raise UsageError("bad setting")

    async def unreachable(stop: asyncio.Event) -> str:
        raise ConnectionFailure("no database")

    async def broken(stop: asyncio.Event) -> str:
        raise RuntimeError("a bug")

    assert run_stoppable(returns) == (0, "done")
    assert run_stoppable(misused) == (2, None)
    assert run_stoppable(unreachable) == (1, None)
    with pytest.raises(RuntimeError, match="a bug"):  # the caller's: logged with its trace
        run_stoppable(broken)

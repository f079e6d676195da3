"""Signals.wait: what a waiting trigger sees of looks, clears and its time limit.

The engine's trigger sleeps on a plain future (common/engine/trigger.py says why); these
pin the behaviour it had with ``asyncio.Event`` + ``wait_for``.
"""

from __future__ import annotations

import asyncio
import threading
import time

import pytest

from common.engine.trigger import Signals
from common.errors import InternalError


async def test_a_look_asked_before_the_wait_returns_at_once_and_is_cleared() -> None:
    s = Signals()
    s.attach()
    s.look()
    assert await s.wait(10.0) is True
    assert await s.wait(0.01) is False  # the look was used up by the first wait


async def test_a_cleared_look_is_forgotten() -> None:
    s = Signals()
    s.attach()
    s.look()
    s.clear()
    started = time.monotonic()
    assert await s.wait(0.05) is False
    assert time.monotonic() - started >= 0.04


async def test_a_look_during_the_wait_ends_it_in_one_loop_iteration() -> None:
    s = Signals()
    s.attach()
    loop = asyncio.get_running_loop()
    loop.call_soon(s.look)
    assert await s.wait(10.0) is True


async def test_a_look_from_another_thread_ends_the_wait() -> None:
    s = Signals()
    s.attach()
    threading.Timer(0.01, s.look_threadsafe).start()
    assert await s.wait(10.0) is True


async def test_no_limit_waits_for_a_look() -> None:
    s = Signals()
    s.attach()
    waiting = asyncio.create_task(s.wait())
    await asyncio.sleep(0.02)
    assert not waiting.done()
    s.look()
    assert await waiting is True


async def test_a_cancelled_wait_leaves_the_next_one_working() -> None:
    s = Signals()
    s.attach()
    waiting = asyncio.create_task(s.wait(10.0))
    await asyncio.sleep(0)
    waiting.cancel()
    with pytest.raises(asyncio.CancelledError):
        await waiting
    s.look()
    assert await s.wait(10.0) is True


async def test_a_look_before_attach_is_ignored_and_wait_needs_attach() -> None:
    s = Signals()
    s.look()
    s.look_threadsafe()
    with pytest.raises(InternalError):
        await s.wait(0.01)
    s.attach()
    assert await s.wait(0.01) is False

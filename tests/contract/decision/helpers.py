"""Helpers of the decision contract tests: play the sim clock, wait with a deadline."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

from common.testing import publish_clock

T = TypeVar("T")


class ClockPlayer:
    """Publishes sim time every ``tick_s`` (rate 0: the service sees exactly ``stamp``)."""

    def __init__(self, session: Any, stamp: float, tick_s: float = 0.02) -> None:
        self.session = session
        self.stamp = stamp
        self.rate = 0.0  # sim seconds per wall second; 0 holds the clock still
        self.tick_s = tick_s
        self._task: asyncio.Task[None] | None = None

    async def _run(self) -> None:
        last = time.monotonic()
        while True:
            now = time.monotonic()
            self.stamp += (now - last) * self.rate
            last = now
            publish_clock(self.session, self.stamp, rate=0.0)
            await asyncio.sleep(self.tick_s)

    def start(self) -> None:
        self._task = asyncio.create_task(self._run())

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            try:
                await self._task
            except asyncio.CancelledError:
                pass


async def wait_until(
    probe: Callable[[], Awaitable[T | None]],
    what: str,
    timeout_s: float = 8.0,
    every_s: float = 0.02,
) -> T:
    """Poll ``probe`` until it returns something truthy; fail after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = await probe()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        await asyncio.sleep(every_s)

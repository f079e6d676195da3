"""Background asyncio tasks: stopping them.

Every service keeps a few long-lived tasks (pollers, tickers, writers) that end by being
cancelled. :func:`cancel_and_wait` is the one way to end them: cancel all first (so they
stop together, not one after another), then wait for each, so nothing still runs once it
returns. Their CancelledError is the expected ending and is swallowed; any other error a task
ended with is raised, as awaiting it would.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Iterable
from typing import Any


async def cancel_and_wait(tasks: Iterable[asyncio.Task[Any]]) -> None:
    pending = list(tasks)
    for task in pending:
        task.cancel()
    for task in pending:
        with contextlib.suppress(asyncio.CancelledError):
            await task

"""The browsers connected over the websocket, and what is pushed to them.

Every message is encoded once and queued for each browser; a browser that falls
:data:`QUEUE_LIMIT` messages behind (a stalled tab, a slow link) is disconnected rather than
left to grow the dashboard's memory: the page reconnects and starts again from a snapshot.
"""

from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import Iterable
from typing import Any, Final

logger = logging.getLogger("pnav.dashboard.hub")

QUEUE_LIMIT: Final = 100


class Browser:
    """One websocket client: its queue of encoded messages."""

    def __init__(self) -> None:
        self.queue: asyncio.Queue[str | None] = asyncio.Queue(maxsize=QUEUE_LIMIT)
        self.dropped = False

    def offer(self, text: str) -> None:
        if self.dropped:
            return
        try:
            self.queue.put_nowait(text)
        except asyncio.QueueFull:
            self.dropped = True
            # make room for the end-of-stream mark the sender waits for
            while not self.queue.empty():
                self.queue.get_nowait()
            self.queue.put_nowait(None)


class Hub:
    def __init__(self) -> None:
        self.browsers: set[Browser] = set()

    def join(self, first: dict[str, Any]) -> Browser:
        """A new browser, whose first message is ``first`` (the snapshot): taken and queued
        with no await in between, so no update falls between the two."""
        browser = Browser()
        browser.offer(encode(first))
        self.browsers.add(browser)
        return browser

    def leave(self, browser: Browser) -> None:
        self.browsers.discard(browser)

    def broadcast(self, messages: Iterable[dict[str, Any]]) -> None:
        for message in messages:
            text = encode(message)
            for browser in list(self.browsers):
                browser.offer(text)
                if browser.dropped:
                    logger.warning("a browser fell %d messages behind: disconnected", QUEUE_LIMIT)
                    self.browsers.discard(browser)

    def close(self) -> None:
        """End every browser's stream (the service is stopping)."""
        for browser in list(self.browsers):
            browser.dropped = True
            while not browser.queue.empty():
                browser.queue.get_nowait()
            browser.queue.put_nowait(None)
        self.browsers.clear()


def encode(message: dict[str, Any]) -> str:
    return json.dumps(message, separators=(",", ":"), allow_nan=False)

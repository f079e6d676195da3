"""The progress bar of ``pnav bench nav``: done/total, the run, elapsed and ETA, on one
line redrawn with a carriage return when the output is a terminal, one line per run when not."""

from __future__ import annotations

import asyncio
import sys
import time
from typing import TextIO


def clock(seconds: float) -> str:
    s = round(seconds)
    return f"{s // 3600}h{s // 60 % 60:02d}m" if s >= 3600 else f"{s // 60}m{s % 60:02d}s"


class Progress:
    """done/total, the run under way, elapsed and ETA. On a terminal one line redrawn in
    place (``\\r``, every second); otherwise one line per run, so a log stays readable."""

    WIDTH = 20

    def __init__(self, total: int, stream: TextIO = sys.stderr, out: TextIO = sys.stdout) -> None:
        self.total, self.stream, self.out, self.done, self.current = total, stream, out, 0, ""
        self.started, self.live, self.shown = time.monotonic(), stream.isatty(), 0

    def line(self) -> str:
        elapsed = time.monotonic() - self.started
        eta = clock(elapsed / self.done * (self.total - self.done)) if self.done else "--"
        fill = self.WIDTH * self.done // max(1, self.total)
        bar = "#" * fill + "." * (self.WIDTH - fill)
        return f"[{bar}] {self.done}/{self.total} {self.current}  {clock(elapsed)}  ETA {eta}"

    def draw(self) -> None:
        if self.live:
            line = self.line()
            self.stream.write("\r" + line + " " * max(0, self.shown - len(line)))
            self.shown = len(line)
            self.stream.flush()

    def begin(self, current: str) -> None:
        self.current = current
        if not self.live:
            print(self.line(), file=self.stream, flush=True)
        self.draw()

    def finish(self, message: str) -> None:
        """One run done: ``message`` goes to ``out`` (stdout) above the bar."""
        self.done += 1
        if self.live:
            self.stream.write("\r" + " " * self.shown + "\r")
            self.shown = 0
        print(message, file=self.out, flush=True)
        self.draw()

    def close(self) -> None:
        """The final state on a line of its own, on a terminal or in a log."""
        self.current = "done"
        self.draw()
        print("" if self.live else self.line(), file=self.stream, flush=True)

    async def tick(self) -> None:
        while True:
            await asyncio.sleep(1.0)
            self.draw()

"""Stack episodes in a worker process, replaced every EPISODES_PER_WORKER episodes.

Each episode launches a whole stack, with the Zenoh router inside the launching process.
Measured here: a process that launches and closes stacks with sensor traffic flowing through
its router grows by about 20 MB per stack (a stack without the bridge subscribing to the
sensors does not), memory the router keeps after it closes. Over the 240 episodes of the
full suite that was 3.6 GB in the benchmark's own process; in a worker that is replaced
every few episodes it is returned to the system instead.
"""

from __future__ import annotations

import asyncio
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from pnav.bench.nav.stack_episode import Episode, Outcome, run_episode

EPISODES_PER_WORKER = 20


def _run(episode: Episode, log_dir: Path) -> Outcome:
    import uvloop

    return uvloop.run(run_episode(episode, log_dir))


class EpisodeWorkers:
    """One episode at a time (the benchmark measures CPU: never two stacks at once)."""

    def __init__(self, episodes_per_worker: int = EPISODES_PER_WORKER) -> None:
        self._pool = ProcessPoolExecutor(
            max_workers=1,
            # spawn: a fresh interpreter, not a fork of one holding a loop and sessions
            mp_context=multiprocessing.get_context("spawn"),
            max_tasks_per_child=episodes_per_worker,
        )

    async def run(self, episode: Episode, log_dir: Path) -> Outcome:
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(self._pool, _run, episode, log_dir)

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)

"""The processes of a running stack, by role, and what they cost: CPU time and peak memory.

Roles: each supervised service (``sim``, ``bridge``, ``controller-2``...), ``postgres`` (the
postmaster and every backend, summed) and ``launcher`` (this process: the in-process Zenoh
router, and the benchmark's own reading). Memory is the proportional set size, so pages
shared between processes (Postgres' shared buffers, the Python runtime) are counted once; the
peak is the highest of the samples taken every ``period_s``.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import psutil

from common.tasks import cancel_and_wait
from pnav.run.launcher import RunningStack


def postmaster(stack: RunningStack) -> psutil.Process | None:
    if stack.local.postgres is None:
        return None  # an external database is not ours to measure
    pid_file = Path(stack.local.postgres.data_dir) / "postmaster.pid"
    return psutil.Process(int(pid_file.read_text().split()[0]))


def roles(stack: RunningStack) -> dict[str, list[psutil.Process]]:
    """Every process of the stack now, grouped by role."""
    # One pass over /proc for the whole tree: asking each process for its children walks
    # every process on the machine once per role, a cost the measured stack would share.
    procs: dict[int, psutil.Process] = {}
    children: dict[int, list[int]] = {}
    for proc in psutil.process_iter(["ppid"]):
        procs[proc.pid] = proc
        children.setdefault(proc.info["ppid"], []).append(proc.pid)

    def tree(pid: int) -> list[psutil.Process]:
        found, todo = [], [pid]
        while todo:
            at = todo.pop()
            if at in procs:
                found.append(procs[at])
            todo.extend(children.get(at, ()))
        return found

    out: dict[str, list[psutil.Process]] = {"launcher": [psutil.Process(os.getpid())]}
    for name, pid in stack.supervisor.pids().items():
        if pid in procs:
            out[name] = tree(pid)
    pm = postmaster(stack)
    if pm is not None:
        out["postgres"] = tree(pm.pid) or [pm]
    return out


def stack_processes(stack: RunningStack) -> list[psutil.Process]:
    return [p for procs in roles(stack).values() for p in procs]


def memory_mb(procs: list[psutil.Process]) -> dict[str, float]:
    pss = rss = 0
    for proc in procs:
        try:
            info = proc.memory_full_info()
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            continue
        pss += getattr(info, "pss", info.rss)
        rss += info.rss
    return {"pss_mb": round(pss / 2**20, 1), "rss_mb": round(rss / 2**20, 1)}


def pss_mb(procs: list[psutil.Process]) -> float:
    """The processes' proportional set size, MB: the ``Pss`` line of each one's
    ``/proc/PID/smaps_rollup`` (what :func:`memory_mb` reads too, without parsing the rest
    of it every second), or :func:`memory_mb`'s where the kernel has no rollup."""
    total = 0
    for proc in procs:
        try:
            with open(f"/proc/{proc.pid}/smaps_rollup", "rb") as f:
                rollup = f.read()
            at = rollup.index(b"\nPss:") + 5
            total += int(rollup[at : rollup.index(b"kB", at)]) * 1024
        except FileNotFoundError:
            if not os.path.exists(f"/proc/{proc.pid}"):
                continue  # it ended
            return memory_mb(procs)["pss_mb"]
        except (ProcessLookupError, PermissionError, ValueError):
            continue
    return round(total / 2**20, 1)


def _cpu_s(proc: psutil.Process) -> float | None:
    try:
        t = proc.cpu_times()
    except (psutil.NoSuchProcess, psutil.AccessDenied):
        return None
    return float(t.user + t.system)


@dataclass
class Usage:
    """CPU seconds per role between start() and stop(), and peak PSS per role."""

    stack: RunningStack
    period_s: float = 1.0
    cpu_start: dict[int, float] = field(default_factory=dict)
    cpu_end: dict[int, float] = field(default_factory=dict)
    role_of: dict[int, str] = field(default_factory=dict)
    peak_mb: dict[str, float] = field(default_factory=dict)
    wall_s: float = 0.0

    def _sample(self, *, first: bool = False) -> None:
        for role, procs in roles(self.stack).items():
            for proc in procs:
                cpu = _cpu_s(proc)
                if cpu is None:
                    continue
                self.role_of[proc.pid] = role
                if first or proc.pid not in self.cpu_start:
                    # a process born during the run counts from zero
                    self.cpu_start[proc.pid] = cpu if first else 0.0
                self.cpu_end[proc.pid] = cpu
            mem = pss_mb(procs)
            self.peak_mb[role] = max(self.peak_mb.get(role, 0.0), mem)

    @contextlib.asynccontextmanager
    async def measuring(self) -> AsyncIterator[Usage]:
        self._sample(first=True)
        t0 = time.monotonic()

        async def sampler() -> None:
            while True:
                await asyncio.sleep(self.period_s)
                await asyncio.to_thread(self._sample)

        task = asyncio.create_task(sampler(), name="usage-sampler")
        try:
            yield self
        finally:
            await cancel_and_wait([task])
            self._sample()
            self.wall_s = time.monotonic() - t0

    def report(self) -> dict[str, dict[str, Any]]:
        """role -> {cpu_s, cpu_percent (of one core), peak_pss_mb}."""
        cpu: dict[str, float] = {}
        for pid, end in self.cpu_end.items():
            role = self.role_of[pid]
            cpu[role] = cpu.get(role, 0.0) + end - self.cpu_start.get(pid, 0.0)
        wall = self.wall_s or 1e-9
        return {
            role: {
                "cpu_s": round(cpu.get(role, 0.0), 2),
                "cpu_percent": round(100.0 * cpu.get(role, 0.0) / wall, 1),
                "peak_pss_mb": round(self.peak_mb.get(role, 0.0), 1),
            }
            for role in sorted(set(cpu) | set(self.peak_mb))
        }

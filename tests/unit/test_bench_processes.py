"""What the benchmarks read of a running stack's processes: its tree by role, and memory."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Iterator
from types import SimpleNamespace
from typing import Any, cast

import psutil
import pytest

from pnav.bench.processes import pss_mb, roles

# a process with a child of its own, both asleep until killed
_PARENT = (
    "import subprocess, sys, time;"
    "subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)']);"
    "time.sleep(60)"
)


@pytest.fixture
def parent() -> Iterator[psutil.Process]:
    process = subprocess.Popen([sys.executable, "-c", _PARENT])
    proc = psutil.Process(process.pid)
    children: list[psutil.Process] = []
    try:
        deadline = time.monotonic() + 10
        while not proc.children() and time.monotonic() < deadline:
            time.sleep(0.02)
        children = proc.children()
        yield proc
    finally:
        process.kill()
        process.wait()
        for child in children:
            child.kill()


def _stack(pids: dict[str, int]) -> Any:
    return SimpleNamespace(
        supervisor=SimpleNamespace(pids=lambda: pids), local=SimpleNamespace(postgres=None)
    )


def test_each_role_holds_its_process_and_every_descendant(parent: psutil.Process) -> None:
    [child] = parent.children()
    found = roles(cast(Any, _stack({"svc": parent.pid, "gone": 2**22 + 1})))
    assert {p.pid for p in found["svc"]} == {parent.pid, child.pid}
    assert [p.pid for p in found["launcher"]] == [psutil.Process().pid]
    assert "gone" not in found  # a process that ended is no one's


def _agrees(procs: list[psutil.Process], alive: list[psutil.Process]) -> bool:
    """Whether pss_mb of ``procs`` read what psutil's full reading of those ``alive`` gives,
    read just before and after it.

    The processes are asleep, but their PSS moves whenever any other process mapping the
    same pages (the interpreter, its libraries) starts or ends: on a busy machine, between
    two readings. So the reading is held to the two around it, and tried again a few times
    (one quiet moment is enough; a wrong reading is wrong in every one)."""
    for _ in range(20):
        before = sum(p.memory_full_info().pss for p in alive) / 2**20
        read = pss_mb(procs)
        after = sum(p.memory_full_info().pss for p in alive) / 2**20
        # pss_mb rounds to 0.1 MB
        if min(before, after) - 0.06 <= read <= max(before, after) + 0.06:
            return True
    return False


def test_pss_is_the_kernel_figure_the_full_memory_reading_gives(parent: psutil.Process) -> None:
    [child] = parent.children()
    procs = [parent, child]
    assert _agrees(procs, procs)
    parent.kill()
    parent.wait(5)
    # an ended process counts for nothing, and the reading goes on with the others
    assert _agrees(procs, [child])

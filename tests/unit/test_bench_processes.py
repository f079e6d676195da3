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


def test_pss_is_the_kernel_figure_the_full_memory_reading_gives(parent: psutil.Process) -> None:
    [child] = parent.children()
    procs = [parent, child]
    expected = sum(p.memory_full_info().pss for p in procs) / 2**20
    assert pss_mb(procs) == pytest.approx(expected, abs=0.5)  # asleep: only sharing moves it
    parent.kill()
    parent.wait(5)
    # an ended process counts for nothing, and the reading goes on with the others
    assert pss_mb(procs) == pytest.approx(child.memory_full_info().pss / 2**20, abs=0.5)

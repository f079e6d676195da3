"""The scratch arrays clearance.py measures pairs in: reused within a thread, never shared
between threads (a controller's threads may decide at once)."""

from __future__ import annotations

import threading

import numpy as np

from pnav_local import scratch


def test_a_name_is_reused_and_grows() -> None:
    a = scratch.array("test", 10)
    b = scratch.array("test", 5)
    assert len(a) == 10 and len(b) == 5 and np.shares_memory(a, b)
    c = scratch.array("test", 1000)
    assert len(c) == 1000 and not np.shares_memory(a, c)
    assert scratch.arange(7).tolist() == list(range(7))
    assert scratch.arange(3000)[-1] == 2999 and not scratch.arange(3).flags.writeable


def test_each_thread_has_its_own() -> None:
    here = scratch.array("test", 100)
    there: list[np.ndarray] = []
    worker = threading.Thread(target=lambda: there.append(scratch.array("test", 100)))
    worker.start()
    worker.join()
    assert len(there) == 1 and not np.shares_memory(here, there[0])

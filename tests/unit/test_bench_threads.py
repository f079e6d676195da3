"""pnav.bench.threads: CPU per role and thread name, from two samples of thread times."""

from __future__ import annotations

import os
import threading

from pnav.bench.threads import sample, shares


def test_shares_are_per_role_and_thread_name_over_threads_seen_twice() -> None:
    before = {
        ("bridge", 10, 10, "python"): 1.0,
        ("bridge", 10, 11, "rx-N"): 0.5,
        ("bridge", 10, 12, "rx-N"): 0.5,
        ("sim", 20, 20, "python"): 3.0,
    }
    after = {
        ("bridge", 10, 10, "python"): 1.5,  # +0.5 s
        ("bridge", 10, 11, "rx-N"): 0.6,  # +0.1 s
        ("bridge", 10, 12, "rx-N"): 0.7,  # +0.2 s: folded with the other rx thread
        ("bridge", 10, 13, "tx-N"): 9.0,  # born between the samples: not counted
        # the sim's thread ended between the samples: not counted either
    }
    assert shares(before, after, seconds=2.0) == {"bridge": {"python": 25.0, "rx-N": 15.0}}


def test_a_sample_reads_every_thread_of_the_processes_given() -> None:
    stop = threading.Event()
    worker = threading.Thread(target=stop.wait)
    worker.start()
    try:
        got = sample({os.getpid(): "launcher"})
        tids = {tid for _role, _pid, tid, _name in got}
        assert worker.native_id in tids and threading.main_thread().native_id in tids
    finally:
        stop.set()
        worker.join()
    assert all(role == "launcher" and cpu >= 0.0 for (role, *_), cpu in got.items())
    assert not any(ch.isdigit() for *_, name in got for ch in name)  # numbers folded

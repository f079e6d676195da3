"""The sim's stop on SIGINT/SIGTERM (services/sim/signals.py): it goes through even when the
signal lands while the main thread holds the stop event's lock, as it does inside
``stop.wait()``. Signals are sent in a child process, never to the test runner."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
import threading
from pathlib import Path

import pytest

from common.errors import UsageError
from services.sim.signals import SignalStop

pytestmark = pytest.mark.timeout(60)

ROOT = Path(__file__).resolve().parents[3]


def run_child(body: str, timeout_s: float = 20.0) -> list[str]:
    """Run ``body`` in a fresh interpreter; its stdout lines (a hang fails the test)."""
    script = "import os, signal, threading, time\n" + textwrap.dedent(body)
    done = subprocess.run(
        [sys.executable, "-c", script],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout.splitlines()


def test_a_stop_signal_landing_while_the_main_thread_holds_the_events_lock_still_stops() -> None:
    # The interleaving that hung the sim once in about fifty fault trials, made certain: the
    # handler runs on the main thread while it holds the event's lock (as inside wait()).
    # A handler that called stop.set() itself would wait for that lock forever.
    lines = run_child(
        """
        from services.sim.signals import SignalStop
        stop = threading.Event()
        signals = SignalStop(stop, dump_after_s=30)
        with stop._cond:  # what Event.wait() holds around its bookkeeping
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(0.3)  # the Python-level handler runs in here, on this thread
        print("stopped" if stop.wait(5) else "still running", flush=True)
        signals.close()
        print(",".join(signals.received))
        """
    )
    assert lines == ["stopped", "SIGTERM"]


def test_a_stop_signal_wakes_a_main_thread_waiting_on_the_event() -> None:
    lines = run_child(
        """
        from services.sim.signals import SignalStop
        stop = threading.Event()
        signals = SignalStop(stop, dump_after_s=30)
        threading.Timer(0.2, os.kill, (os.getpid(), signal.SIGINT)).start()
        started = time.monotonic()
        while not stop.is_set() and time.monotonic() - started < 10:
            stop.wait(0.0005)  # the sim's loop between steps
        print("stopped" if stop.is_set() else "still running", flush=True)
        signals.close()
        """
    )
    assert lines == ["stopped"]


def test_a_second_signal_is_heard_and_the_stop_stands() -> None:
    lines = run_child(
        """
        from services.sim.signals import SignalStop
        stop = threading.Event()
        signals = SignalStop(stop, dump_after_s=30)
        os.kill(os.getpid(), signal.SIGTERM)
        stop.wait(5)
        os.kill(os.getpid(), signal.SIGINT)
        deadline = time.monotonic() + 5
        while len(signals.received) < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        signals.close()
        print(stop.is_set(), ",".join(signals.received))
        """
    )
    assert lines == ["True SIGTERM,SIGINT"]


def test_close_gives_the_signals_back_their_handlers() -> None:
    before = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    fd_before = signal.set_wakeup_fd(-1)
    signal.set_wakeup_fd(fd_before)
    signals = SignalStop(threading.Event())
    assert signal.getsignal(signal.SIGTERM) is not before[signal.SIGTERM]
    signals.close()
    assert {sig: signal.getsignal(sig) for sig in before} == before
    assert signal.set_wakeup_fd(fd_before) == fd_before  # the wakeup fd it found, back


def test_it_must_be_made_on_the_main_thread() -> None:
    errors: list[BaseException] = []

    def make() -> None:
        try:
            SignalStop(threading.Event())
        except UsageError as exc:
            errors.append(exc)

    worker = threading.Thread(target=make)
    worker.start()
    worker.join()
    assert len(errors) == 1

"""Stopping the sim on SIGINT and SIGTERM without taking a lock inside a signal handler.

The sim is a synchronous program: its main thread steps the physics and sleeps in
``stop.wait(...)`` between steps, ``stop`` being a ``threading.Event``. Python runs a
signal's handler on the main thread, between two bytecodes of whatever it was doing, and
that may be inside ``stop.wait()`` while it holds the event's internal lock (a plain,
non-reentrant ``Lock``). A handler calling ``stop.set()`` then waits for a lock its own
thread holds, forever: the sim logged "stopping" and hung until the launcher killed it, about
once in fifty fault trials (python/cpython#126434 is the same trap with
``multiprocessing.Event``).

So the handler does nothing itself. Python's C-level handler writes the signal's number to a
pipe (``signal.set_wakeup_fd``: a ``write(2)``, no lock), and a thread of its own reads the
pipe and stops the sim from an ordinary thread context: it logs, arms the stack dump for a
stop that hangs, and sets ``stop``.
"""

from __future__ import annotations

import faulthandler
import logging
import os
import signal
import threading
from types import FrameType

from common.errors import UsageError
from common.log import event

log = logging.getLogger("services.sim")

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
# after a stop signal, how long the sim may take to stop before every thread's stack is
# written to the log (the launcher kills it after 8 s)
STOP_DUMP_S = 5.0


def _ignore(_signum: int, _frame: FrameType | None) -> None:
    """The Python-level handler: present so that the C-level one runs and writes the
    wakeup byte (and the default action, death, does not happen); nothing else."""


class SignalStop:
    """Sets ``stop`` when SIGINT or SIGTERM arrives; :meth:`close` puts everything back.

    Construct it on the main thread (``signal.set_wakeup_fd`` may only be set there), before
    the work that waits on ``stop``.
    """

    def __init__(self, stop: threading.Event, dump_after_s: float = STOP_DUMP_S) -> None:
        if threading.current_thread() is not threading.main_thread():
            raise UsageError("SignalStop must be created on the main thread")
        self.stop = stop
        self.dump_after_s = dump_after_s
        self.received: list[str] = []  # the names of the signals heard, in order
        self._read, self._write = os.pipe()
        os.set_blocking(self._write, False)  # set_wakeup_fd requires it
        self._previous_fd = signal.set_wakeup_fd(self._write, warn_on_full_buffer=False)
        self._previous = {sig: signal.signal(sig, _ignore) for sig in STOP_SIGNALS}
        self._thread = threading.Thread(target=self._listen, name="stop-signals", daemon=True)
        self._thread.start()

    def _listen(self) -> None:
        wanted = {int(sig) for sig in STOP_SIGNALS}
        while True:
            try:
                data = os.read(self._read, 64)
            except OSError:  # closed: close() ran
                return
            if not data:
                return
            for signum in data:
                if signum in wanted:
                    self._on_signal(signal.Signals(signum))

    def _on_signal(self, sig: signal.Signals) -> None:
        self.received.append(sig.name)
        if self.stop.is_set():
            event(log, logging.INFO, "already stopping", signal=sig.name)
            return
        event(log, logging.INFO, "stopping", signal=sig.name)
        # A stop that hangs writes every thread's stack to the log before the launcher's
        # SIGKILL, so the next hang names its place; cancelled by close() once stopped.
        faulthandler.dump_traceback_later(self.dump_after_s, exit=False)
        self.stop.set()

    def close(self) -> None:
        """The stop went through (or the sim ends): cancel the stack dump, give the signals
        back their previous handlers and stop listening."""
        faulthandler.cancel_dump_traceback_later()
        for sig, previous in self._previous.items():
            signal.signal(sig, previous)
        signal.set_wakeup_fd(self._previous_fd)
        os.close(self._write)  # the listener's read returns b"": it ends
        self._thread.join(timeout=1.0)
        os.close(self._read)

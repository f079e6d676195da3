"""Tie a service process's life to its launcher's, so no process is left behind.

When ``pnav up`` starts a service it sets ``PNAV_PARENT_PID``. The service then asks Linux to
send it SIGTERM when its parent dies (``prctl(PR_SET_PDEATHSIG)``), so even a launcher killed
with SIGKILL takes its services with it. Elsewhere this does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import sys

_PR_SET_PDEATHSIG = 1


def die_with_parent() -> None:
    expected = os.environ.get("PNAV_PARENT_PID", "").strip()
    if not expected or not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        return
    # The parent may have died before prctl took effect: then we were re-parented already.
    if str(os.getppid()) != expected:
        os.kill(os.getpid(), signal.SIGTERM)

"""``python -m examples.sql_controller``: run the example controller until SIGTERM/SIGINT.

Exit codes, as the shipped services use them: 0 after a clean stop, 1 when it failed (no
database, no router, no contract), 2 when a PNAV_* variable is wrong.
"""

from __future__ import annotations

import asyncio
import ctypes
import ctypes.util
import logging
import os
import signal
import sys

import asyncpg
import zenoh

from examples.sql_controller.controller import run
from examples.sql_controller.environment import ConfigError, Settings

logger = logging.getLogger("sql_controller")


def die_with_parent() -> None:
    """Under ``pnav up``'s supervisor (PNAV_PARENT_PID set), ask Linux for a SIGTERM when the
    launcher dies, even by SIGKILL, so no controller outlives its stack."""
    parent = os.environ.get("PNAV_PARENT_PID", "").strip()
    if not parent or not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # 1: PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if str(os.getppid()) != parent:  # it died before prctl took effect
        os.kill(os.getpid(), signal.SIGTERM)


async def serve(settings: Settings) -> None:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        # a signal only asks: the tick under way finishes and the robots are given back
        loop.add_signal_handler(sig, stop.set)
    await run(settings, stop)


def main() -> int:
    try:
        settings = Settings.from_env()
        if not isinstance(logging.getLevelName(settings.log_level), int):
            raise ConfigError(f"PNAV_LOG_LEVEL={settings.log_level!r} is not a log level")
    except ConfigError as exc:
        print(f"sql_controller: {exc}", file=sys.stderr)
        return 2
    logging.basicConfig(
        level=settings.log_level,
        format="%(asctime)s %(levelname)s sql_controller %(message)s",
        stream=sys.stderr,
    )
    die_with_parent()
    try:
        asyncio.run(serve(settings))
    except (OSError, asyncpg.PostgresError, zenoh.ZError) as exc:
        # no database, no router, or a database without the contract: say so, no traceback
        logger.error("cannot run: %s", exc)
        return 1
    except Exception:
        logger.exception("failed")
        return 1
    logger.info("stopped")
    return 0


if __name__ == "__main__":
    sys.exit(main())

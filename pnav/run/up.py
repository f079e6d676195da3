"""``pnav up``: run the whole stack in the foreground until Ctrl-C or SIGTERM."""

from __future__ import annotations

import asyncio
import logging
import signal
from pathlib import Path

from common import log
from common.errors import UsageError
from common.postmaster import clean_up
from pnav.run import stackfile
from pnav.run.launcher import launched
from pnav.run.stack_options import StackOptions

logger = logging.getLogger("pnav.up")


def clean_leftover() -> None:
    """A stack that died without cleaning up (its watcher killed too) may have left its
    embedded Postgres running and its temporary data directory: stop and remove them (a
    kept ``--data-dir`` is only stopped)."""
    dead = stackfile.leftover()
    if dead is None:
        return
    if dead.postgres_dir:
        data_dir = Path(dead.postgres_dir)
        clean_up(data_dir, remove=dead.postgres_temporary)
        log.event(
            logger,
            logging.INFO,
            "cleaned up after a stack that died",
            pid=dead.pid,
            postgres=str(data_dir),
            removed=dead.postgres_temporary,
        )
    stackfile.forget(dead)


async def up(options: StackOptions) -> int:
    running = stackfile.read()
    if running is not None:
        raise UsageError(
            f"a stack is already running (pid {running.pid}, world {running.world}): "
            "stop it with `pnav down` first"
        )
    log.setup("pnav-up")
    clean_leftover()
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    async with launched(options) as stack:
        log.event(
            logger,
            logging.INFO,
            "stack up",
            world=stack.world_path.stem,
            rate=options.rate,
            database=stack.local.database_url,
            zenoh=stack.local.zenoh.connect[0],
            logs=str(stack.log_dir),
            processes=",".join(stack.supervisor.children),
            replicas=",".join(f"{k}={v}" for k, v in sorted(options.replicas.items())) or "-",
            dashboard=stack.dashboard_url or "off",
        )
        print(
            "stack up: `pnav status` to watch, `pnav goal X Y` to send the robot, "
            "Ctrl-C or `pnav down` to stop",
            flush=True,
        )
        if stack.dashboard_url:
            print(f"dashboard: {stack.dashboard_url}", flush=True)
        await stop.wait()
        logger.info("stopping")
    logger.info("stack down")
    if options.record is not None:
        print(f"recorded to {options.record}: `pnav record info {options.record}`", flush=True)
    return 0

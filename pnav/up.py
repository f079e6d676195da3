"""``pnav up``: run the whole stack in the foreground until Ctrl-C or SIGTERM."""

from __future__ import annotations

import asyncio
import logging
import signal

from common import log
from common.errors import UsageError
from pnav import stackfile
from pnav.launcher import StackOptions, launched

logger = logging.getLogger("pnav.up")


async def up(options: StackOptions) -> int:
    running = stackfile.read()
    if running is not None:
        raise UsageError(
            f"a stack is already running (pid {running.pid}, world {running.world}): "
            "stop it with `pnav down` first"
        )
    log.setup("pnav-up")
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
            services=",".join(stack.supervisor.children),
            replicas=",".join(f"{k}={v}" for k, v in sorted(options.replicas.items())) or "-",
        )
        print(
            "stack up: `pnav status` to watch, `pnav goal X Y` to send the robot, "
            "Ctrl-C or `pnav down` to stop",
            flush=True,
        )
        await stop.wait()
        logger.info("stopping")
    logger.info("stack down")
    return 0

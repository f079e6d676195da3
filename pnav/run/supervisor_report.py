"""The launcher's supervisor, told to the stack: ``pnav/supervisor/{launcher}`` on Zenoh.

The supervisor (pnav/run/process_supervisor.py) is the launcher's, not a service's, and knows
what no table records: how often it restarted each process. :class:`SupervisorReport` publishes it
(msgpack, CONTRACT.md "Supervisor reports") when the stack starts, after every exit and
restart, and every ``period_s`` so a reader that joins late hears it within a period. The
dashboard's ``/metrics`` turns it into ``pnav_supervisor_restarts_total``.

It is put on the launcher's router's own session, not a client's: the router's access control
(common.contract.acl), which lets no client put ``pnav/supervisor/*``, does not apply to it.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import socket

import zenoh

from common import bus
from common.contract import keys
from pnav.run.process_supervisor import Supervisor

log = logging.getLogger("pnav.supervisor")

PERIOD_S = 2.0


def launcher_id() -> str:
    """``<host>-<pid>`` of this launcher, safe in one key chunk (as PNAV_INSTANCE's default)."""
    host = "".join(c if c.isalnum() or c in "_-" else "-" for c in socket.gethostname())
    return f"launcher-{host}-{os.getpid()}"


class SupervisorReport:
    def __init__(
        self, supervisor: Supervisor, session: zenoh.Session, *, period_s: float = PERIOD_S
    ) -> None:
        self.supervisor, self.session, self.period_s = supervisor, session, period_s
        self.launcher = launcher_id()
        self.key = keys.supervisor_key(self.launcher)
        self._task: asyncio.Task[None] | None = None

    def publish(self) -> None:
        body = {"launcher": self.launcher, "processes": self.supervisor.status()}
        try:
            self.session.put(self.key, bus.pack(body))
        except Exception:
            log.warning("could not publish the supervisor report", exc_info=True)

    def start(self) -> None:
        self.supervisor.on_change.append(self.publish)
        self.publish()
        self._task = asyncio.create_task(self._every_period(), name="supervisor-report")

    async def _every_period(self) -> None:
        while True:
            await asyncio.sleep(self.period_s)
            self.publish()

    async def close(self) -> None:
        with contextlib.suppress(ValueError):
            self.supervisor.on_change.remove(self.publish)
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None

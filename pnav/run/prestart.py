"""``python -m pnav.run.prestart MODULE [ARGS...]``: a service process started before its
environment exists.

The launcher starts each service this way while it is still making Postgres ready
(:class:`Prestart`, taken by pnav.run.process_supervisor): the process imports the service's code
(a third of a second to a second of a 2-core machine's time, per process) in parallel with the
launcher's own work, then waits. When the stack is ready the launcher writes the service's
whole environment (its role's DSN, its Zenoh password...) as JSON on a pipe (the descriptor
in ``PNAV_PRESTART_FD``) and closes it; the process takes that environment as its own and
runs ``MODULE`` as ``python -m MODULE ARGS...`` would. A pipe closed with nothing written
(the launcher gave up, or died) ends the process with code 0.

A module may define ``prestart(args)`` to import what it would otherwise import later
(pnav.run.host: the services it hosts; the sim: its node). Nothing reads the environment at
import time: every setting is read by the service's entry, after the environment arrived.

The launcher's side is :class:`Prestart` (pnav.run.launcher starts them,
pnav.run.process_supervisor takes them); the process's side is :func:`main`.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import json
import os
import runpy
import sys
from dataclasses import dataclass

GATE = "PNAV_PRESTART_FD"


@dataclass
class Warm:
    """A process started before its environment (pnav.run.prestart), waiting on ``gate``."""

    argv: list[str]
    process: asyncio.subprocess.Process
    gate: int  # the write end of its pipe
    env: dict[str, str]  # what it was started with


# what only an interpreter's start reads: a process started without the final value of one
# of these is not used (a new one is started)
_AT_EXEC = ("PYTHON", "LD_", "MALLOC_")


class Prestart:
    """The service processes started while the launcher makes the stack ready, each up to
    the end of its imports (pnav.run.prestart): the supervisor takes them instead of starting
    new ones. ``PNAV_PRESTART=0`` starts none."""

    def __init__(self) -> None:
        self.warm: dict[str, Warm] = {}
        self._leaving: list[asyncio.subprocess.Process] = []  # let go, to reap

    @staticmethod
    def enabled() -> bool:
        return os.environ.get("PNAV_PRESTART", "").strip().lower() not in ("0", "false", "no")

    async def start(self, plan: list[tuple[str, list[str]]]) -> None:
        """Start each ``(name, argv)`` of ``plan`` that runs ``python -m MODULE``."""
        if not self.enabled():
            return
        for name, argv in plan:
            if len(argv) < 3 or argv[:2] != [sys.executable, "-m"]:
                continue  # not a module of ours to import ahead (a --replace command)
            read, write = os.pipe()  # neither end is inherited but the read end, passed
            env = {**os.environ, "PNAV_PARENT_PID": str(os.getpid())}
            try:
                process = await asyncio.create_subprocess_exec(
                    sys.executable,
                    "-m",
                    "pnav.run.prestart",
                    *argv[2:],
                    env={**env, GATE: str(read)},
                    stdout=asyncio.subprocess.PIPE,
                    stderr=asyncio.subprocess.STDOUT,
                    start_new_session=True,
                    pass_fds=(read,),
                )
            except BaseException:
                os.close(write)
                raise
            finally:
                os.close(read)
            self.warm[name] = Warm(argv, process, write, env)

    def take(self, name: str, argv: list[str], env: dict[str, str]) -> Warm | None:
        """The process started for ``name`` with ``env`` sent to it, if it runs ``argv``
        and was started with what ``env`` gives the interpreter's start; else None (and
        it is let go)."""
        warm = self.warm.pop(name, None)
        if warm is None:
            return None
        started = {k: v for k, v in warm.env.items() if k.startswith(_AT_EXEC)}
        wanted = {k: v for k, v in env.items() if k.startswith(_AT_EXEC)}
        if warm.argv != argv or started != wanted or warm.process.returncode is not None:
            self._let_go(warm)
            return None
        data = json.dumps(env).encode()
        try:
            while data:  # a pipe's buffer holds any environment; a child reads it at once
                data = data[os.write(warm.gate, data) :]
        except OSError:
            self._let_go(warm)
            return None
        os.close(warm.gate)
        return warm

    def _let_go(self, warm: Warm) -> None:
        """Close its pipe empty: the process ends on its own (pnav.run.prestart)."""
        with contextlib.suppress(OSError):
            os.close(warm.gate)
        self._leaving.append(warm.process)

    async def close(self, wait_s: float = 5.0) -> None:
        """Let every process not taken go, and reap them."""
        for warm in list(self.warm.values()):
            self._let_go(warm)
        self.warm.clear()
        for process in self._leaving:
            try:
                await asyncio.wait_for(process.communicate(), wait_s)
            except TimeoutError:
                with contextlib.suppress(ProcessLookupError):
                    process.kill()
                await process.wait()
        self._leaving.clear()


def warm(module: str, args: list[str]) -> None:
    """Import ``module``'s code as ``python -m module`` will run it, without running it."""
    imported = importlib.import_module(module)
    if hasattr(imported, "__path__"):  # a package: -m runs its __main__
        imported = importlib.import_module(f"{module}.__main__")
    hook = getattr(imported, "prestart", None)
    if callable(hook):
        hook(args)


def wait_for_environment(fd: int) -> dict[str, str] | None:
    """The environment the launcher writes on ``fd``, or None if it closed it empty."""
    with os.fdopen(fd, "rb") as gate:
        data = gate.read()
    if not data:
        return None
    env: dict[str, str] = json.loads(data)
    return env


def main() -> int:
    if len(sys.argv) < 2:
        print("usage: python -m pnav.run.prestart MODULE [ARGS...]", file=sys.stderr)
        return 2
    module, args = sys.argv[1], sys.argv[2:]
    fd = int(os.environ.pop(GATE))
    warm(module, args)
    env = wait_for_environment(fd)
    if env is None:
        return 0
    os.environ.clear()
    os.environ.update(env)
    sys.argv = [module, *args]
    runpy.run_module(module, run_name="__main__", alter_sys=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``python -m pnav.prestart MODULE [ARGS...]``: a service process started before its
environment exists.

The launcher starts each service this way while it is still making Postgres ready
(pnav.supervisor, ``Supervisor.prestart``): the process imports the service's code (a third
of a second to a second of a 2-core machine's time, per process) in parallel with the
launcher's own work, then waits. When the stack is ready the launcher writes the service's
whole environment (its role's DSN, its Zenoh password...) as JSON on a pipe (the descriptor
in ``PNAV_PRESTART_FD``) and closes it; the process takes that environment as its own and
runs ``MODULE`` as ``python -m MODULE ARGS...`` would. A pipe closed with nothing written
(the launcher gave up, or died) ends the process with code 0.

A module may define ``prestart(args)`` to import what it would otherwise import later
(pnav.host: the services it hosts). Nothing reads the environment at import time: every
setting is read by the service's entry, after the environment arrived.
"""

from __future__ import annotations

import importlib
import json
import os
import runpy
import sys

GATE = "PNAV_PRESTART_FD"


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
        print("usage: python -m pnav.prestart MODULE [ARGS...]", file=sys.stderr)
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

"""Where a running stack's CPU goes, process by process and thread by thread.

``python -m pnav.bench.threads [--seconds S]`` finds the processes of the stacks running on
this machine (``python -m services.*``, Postgres, the ``pnav`` launcher), reads the CPU time
of every thread twice, S seconds apart, and prints each role's share of one core split by
thread name: ``python`` / ``pnav`` is the interpreter's main thread (the event loop, the
rules, asyncpg, msgpack), ``rx-N`` / ``tx-N`` / ``acc-N`` / ``app-N`` are Zenoh's runtime
threads (its transport receive and send, the accept loop, the callbacks' pool). Numbered
thread names are folded (``rx-3`` counts as ``rx-N``). Run it beside ``pnav bench latency``
or ``pnav bench nav``; it only reads ``/proc``, so it costs the stack nothing.
"""

from __future__ import annotations

import argparse
import json
import re
import time
from pathlib import Path

import psutil

Sample = dict[tuple[str, int, int, str], float]  # (role, pid, tid, thread name) -> CPU s

_SERVICE = re.compile(r"-m services\.(\w+)")


def stack_processes() -> dict[int, str]:
    """pid -> role of every stack process running now."""
    roles: dict[int, str] = {}
    for proc in psutil.process_iter(["pid", "cmdline", "name"]):
        cmdline = " ".join(proc.info["cmdline"] or [])
        service = _SERVICE.search(cmdline)
        if service:
            roles[proc.pid] = service.group(1)
        elif proc.info["name"] == "postgres":
            roles[proc.pid] = "postgres"
        elif "bin/pnav " in cmdline or "spawn_main" in cmdline:
            roles[proc.pid] = "launcher"
    return roles


def _thread_name(pid: int, tid: int) -> str:
    try:
        name = Path(f"/proc/{pid}/task/{tid}/comm").read_text().strip()
    except OSError:
        return "?"
    return re.sub(r"\d+", "N", name)


def sample(roles: dict[int, str]) -> Sample:
    out: Sample = {}
    for pid, role in roles.items():
        try:
            threads = psutil.Process(pid).threads()
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            continue
        for t in threads:
            out[(role, pid, t.id, _thread_name(pid, t.id))] = t.user_time + t.system_time
    return out


def shares(before: Sample, after: Sample, seconds: float) -> dict[str, dict[str, float]]:
    """role -> {thread name: % of one core}, over the threads seen in both samples."""
    per: dict[tuple[str, str], float] = {}
    for key, cpu in after.items():
        if key in before:
            which = (key[0], key[3])
            per[which] = per.get(which, 0.0) + cpu - before[key]
    out: dict[str, dict[str, float]] = {}
    for (role, name), cpu in per.items():
        out.setdefault(role, {})[name] = round(100.0 * cpu / seconds, 1)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pnav.bench.threads")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--json", type=Path, help="also write the figures here")
    args = parser.parse_args(argv)
    roles = stack_processes()
    if not roles:
        print("no stack processes running")
        return 1
    first = sample(roles)
    time.sleep(args.seconds)
    result = shares(first, sample(roles), args.seconds)
    for role in sorted(result, key=lambda r: -sum(result[r].values())):
        threads = result[role]
        print(f"{role:12s} {sum(threads.values()):6.1f} % of a core")
        for name, pct in sorted(threads.items(), key=lambda kv: -kv[1]):
            if pct >= 0.2:
                print(f"    {name:20s} {pct:6.1f}")
    if args.json is not None:
        args.json.write_text(json.dumps({"seconds": args.seconds, "percent": result}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""A sample's wait for the GIL: ``python -m pnav.bench.gil_wait``.

Zenoh delivers every sample on a thread of its own, which needs the GIL to run the Python
callback (``common.bus.subscribe_threaded``; ``bus.subscribe``'s hand-over to the loop too).
While another thread of the process runs Python (the sim's physics, a long activation), that
thread waits until the running one lets go: at the latest after the interpreter's switch
interval, Python's default 5 ms, or a shorter one (``--short-ms``, 0.5 ms by default). A
shorter one was tried in every process with a session and measured worse at low load
(docs/BENCHMARKS.md, "Sense-to-act latency: where the milliseconds go"), so the stack
keeps Python's; this measures what the interval does to a threaded handler alone.

This measures it with the stack's own pieces: a process of its own puts a stamped sample
every ~10 ms through a Zenoh router (in a process of its own, as the launcher's is); this
process's main thread runs Python ``--busy-ms`` at a time with a 0.2 ms pause between (a
sim stepping its fleet), and a threaded subscriber stamps each sample's arrival. Both
intervals, alternately, ``--rounds`` times each; delays put -> handler, on CLOCK_MONOTONIC.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from typing import Any

from common import bus
from common.config import ZenohSettings
from pnav.bench.figures import emit, machine, percentiles
from pnav.bench.hop import router_process

KEY = "pnav/bench/gil_wait"
DEFAULT_S = 0.005  # Python's own switch interval
PUBLISHER = """
import sys, time
from common import bus
from common.config import ZenohSettings
session = bus.open_session(ZenohSettings(mode="client", connect=(sys.argv[1],)))
time.sleep(1.0)  # the subscriber's interest reaches the router
for i in range(int(sys.argv[2])):
    session.put(sys.argv[3], bus.pack({"sent": time.monotonic_ns()}))
    time.sleep(0.0107)  # not a multiple of the busy stretch
session.close()
"""


def one_round(
    settings: ZenohSettings, interval_s: float, samples: int, busy_s: float
) -> list[float]:
    """Delays (ms) of ``samples`` samples with the switch interval at ``interval_s``."""
    session = bus.open_session(settings)
    before = sys.getswitchinterval()
    sys.setswitchinterval(interval_s)
    delays: list[float] = []

    def on_sample(key: str, payload: bytes) -> None:
        delays.append((time.monotonic_ns() - bus.unpack(payload)["sent"]) / 1e6)

    subscriber = bus.subscribe_threaded(session, KEY, on_sample)
    publisher = subprocess.Popen(
        [sys.executable, "-c", PUBLISHER, settings.connect[0], str(samples), KEY]
    )
    try:
        while publisher.poll() is None:
            until = time.perf_counter() + busy_s
            while time.perf_counter() < until:
                pass  # Python holding the GIL, as a step of the sim's physics does
            time.sleep(0.0002)
    finally:
        publisher.wait()
        subscriber.undeclare()
        session.close()
        sys.setswitchinterval(before)
    return delays


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pnav.bench.gil_wait", description=__doc__)
    parser.add_argument("--samples", type=int, default=300, help="samples per round")
    parser.add_argument("--busy-ms", type=float, default=20.0, help="Python held at a time")
    parser.add_argument("--rounds", type=int, default=2, help="rounds per interval")
    parser.add_argument("--short-ms", type=float, default=0.5, help="the shorter interval")
    parser.add_argument("--json", metavar="FILE", help="write the figures as JSON ('-': stdout)")
    args = parser.parse_args(argv)
    intervals = {"python_default": DEFAULT_S, "short": args.short_ms / 1000}
    delays: dict[str, list[float]] = {name: [] for name in intervals}
    with router_process() as settings:
        for _ in range(args.rounds):
            for name, interval in intervals.items():
                delays[name] += one_round(settings, interval, args.samples, args.busy_ms / 1000)
    result: dict[str, Any] = {
        "benchmark": "gil_wait",
        "machine": machine(),
        "busy_ms": args.busy_ms,
    }
    print(f"put -> threaded handler, ms, main thread busy {args.busy_ms:g} ms at a time")
    for name, interval in intervals.items():
        figures = percentiles(delays[name])
        result[name] = {
            "switch_interval_ms": interval * 1000,
            "samples": len(delays[name]),
            **figures,
        }
        print(
            f"  switch interval {interval * 1000:.1f} ms: {len(delays[name])} samples, "
            f"p50 {figures['p50']:.2f} p95 {figures['p95']:.2f} p99 {figures['p99']:.2f} "
            f"max {figures['max']:.2f}"
        )
    emit(result, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())

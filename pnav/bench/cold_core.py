"""The same Python, back to back and once every 50 ms: ``python -m pnav.bench.cold_core``.

At one robot at 20 Hz every process of the stack runs a millisecond or two of Python every
50 ms and sleeps in between; at ten robots the samples come 5 ms apart. This times one
piece of work shaped like a meta rule's (a few dozen frozen dataclasses built and compared,
as the meta-controller builds its robots' scenario specs) ``--calls`` times back to back,
then with ``--gap-ms`` of sleep before each call, alternately, ``--rounds`` times: what the
stack's rules pay per run when their process has been idle (its caches cold, a halted vCPU
woken) against when it is busy. docs/BENCHMARKS.md, "Sense-to-act latency: where the
milliseconds go".
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from typing import Any

from pnav.bench.figures import emit, machine, percentiles


@dataclass(frozen=True)
class Spec:
    robot: str
    strategy: str
    params: tuple[tuple[str, float], ...]


def work() -> bool:
    """About 60 us of Python on a warm core: specs built, rebuilt and compared."""
    specs = {(f"r{i % 3}", i): Spec(f"r{i % 3}", "GOTO", (("a", i), ("b", 2.0))) for i in range(60)}
    again = {k: Spec(v.robot, v.strategy, v.params) for k, v in specs.items()}
    return specs == again


def timed(calls: int, gap_s: float) -> list[float]:
    """Microseconds per call, each call after ``gap_s`` of sleep (0: back to back)."""
    out: list[float] = []
    for _ in range(calls):
        if gap_s:
            time.sleep(gap_s)
        started = time.perf_counter()
        work()
        out.append((time.perf_counter() - started) * 1e6)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pnav.bench.cold_core", description=__doc__)
    parser.add_argument("--calls", type=int, default=200, help="calls per round and mode")
    parser.add_argument("--gap-ms", type=float, default=50.0, help="sleep before each call")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--json", metavar="FILE", help="write the figures as JSON ('-': stdout)")
    args = parser.parse_args(argv)
    modes = {"back_to_back": 0.0, "after_a_gap": args.gap_ms / 1000}
    times: dict[str, list[float]] = {name: [] for name in modes}
    for _ in range(args.rounds):
        for name, gap in modes.items():
            times[name] += timed(args.calls, gap)
    result: dict[str, Any] = {"benchmark": "cold_core", "machine": machine(), "gap_ms": args.gap_ms}
    print(f"one meta-rule-sized piece of Python, us per call ({args.calls * args.rounds} calls)")
    for name, gap in modes.items():
        figures = percentiles(times[name], (50, 90))
        result[name] = figures
        p50, p90 = figures["p50"], figures["p90"]
        print(f"  {gap * 1000:4.0f} ms idle before each: p50 {p50:.1f} p90 {p90:.1f}")
    emit(result, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())

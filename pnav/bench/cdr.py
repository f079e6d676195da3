"""``python -m pnav.bench.cdr``: what the ROS 2 robot link's CDR costs per sample, beside msgpack.

For each message the ROS 2 link carries (LaserScan of 360 and 720 beams, Odometry, Twist) it
times, per sample and on one core, the very functions the link runs:

- the sending side: ``build`` (the contract's body -> a rosbags message: the sim's
  ``ros2wire`` for sensors, the bridge's ``ros2msgs.twist`` for cmd_vel) and ``encode``
  (``ros2types.encode``, CDR);
- the receiving side: ``decode`` (``ros2types.decode``) and ``convert`` (the message -> the
  contract's body: the bridge's ``ros2msgs.scan_body``/``odom_body``; for a Twist, the two
  floats the sim reads);
- the native link's ``pack`` and ``unpack`` (msgpack, ``common.bus``) of the same body.

Each figure is the median over ``--repeats`` batches of ``--samples`` calls (and the fastest
batch), in microseconds; on a loaded machine the fastest batch is the steadier figure.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from common import bus, ros2types
from pnav.bench.figures import emit, machine
from services.bridge import ros2msgs
from services.sim import ros2wire

STEPS = ("build", "encode", "decode", "convert", "pack", "unpack")


@dataclass(frozen=True)
class Case:
    """One message: its contract body and the link's functions over it."""

    name: str
    type_name: str
    body: dict[str, Any]
    build: Callable[[dict[str, Any]], Any]
    convert: Callable[[Any], dict[str, Any]]


def scan_body(beams: int, fov: float, seed: int = 0) -> dict[str, Any]:
    """A sweep as the sim sends it: ranges within 0.12..3.5 m, one in ten beyond (inf)."""
    rng = np.random.default_rng(seed)
    ranges = rng.uniform(0.2, 3.4, beams)
    ranges[rng.random(beams) < 0.1] = math.inf
    full = math.isclose(fov, math.tau)
    return {
        "stamp": 12.345,
        "seq": 7,
        "angle_min": 0.0 if full else -fov / 2,
        "angle_increment": fov / beams if full else fov / (beams - 1),
        "range_min": 0.12,
        "range_max": 3.5,
        "ranges": ranges.tolist(),
    }


ODOM_BODY: dict[str, Any] = {
    "stamp": 12.345, "seq": 7, "x": 1.5, "y": -2.25, "yaw": 0.75, "linear": 0.22, "angular": -0.4,
}  # fmt: skip
TWIST_BODY: dict[str, Any] = {
    "stamp": 12.345, "linear": 0.22, "angular": -0.4, "command_id": 123456, "decided_stamp": 12.3,
}  # fmt: skip


def _twist_convert(msg: Any) -> dict[str, Any]:
    return {"linear": float(msg.linear.x), "angular": float(msg.angular.z)}


def _scan_build(body: dict[str, Any]) -> Any:
    return ros2wire.scan_msg(body, "r1/base_scan")


def cases() -> list[Case]:
    scan_build = _scan_build
    return [
        Case(
            "LaserScan 360",
            ros2types.LASER_SCAN,
            scan_body(360, math.tau),
            scan_build,
            lambda msg: ros2msgs.scan_body(msg, 7),
        ),
        Case(
            "LaserScan 720",
            ros2types.LASER_SCAN,
            scan_body(720, math.radians(270)),
            scan_build,
            lambda msg: ros2msgs.scan_body(msg, 7),
        ),
        Case(
            "Odometry",
            ros2types.ODOMETRY,
            ODOM_BODY,
            lambda body: ros2wire.odom_msg(body, "r1/odom", "r1/base_footprint"),
            lambda msg: ros2msgs.odom_body(msg, 7, None),
        ),
        Case(
            "Twist",
            ros2types.TWIST,
            TWIST_BODY,
            lambda body: ros2msgs.twist(body["linear"], body["angular"]),
            _twist_convert,
        ),
    ]


def per_call_us(fn: Callable[[], Any], samples: int, repeats: int) -> dict[str, float]:
    """Median and fastest of ``repeats`` batches of ``samples`` calls, per call in µs."""
    batches = []
    for _ in range(repeats):
        t0 = time.perf_counter_ns()
        for _ in range(samples):
            fn()
        batches.append((time.perf_counter_ns() - t0) / samples / 1e3)
    return {"median_us": round(statistics.median(batches), 2), "min_us": round(min(batches), 2)}


def measure(case: Case, samples: int, repeats: int) -> dict[str, Any]:
    msg = case.build(case.body)
    cdr = ros2types.encode(case.type_name, msg)
    decoded = ros2types.decode(case.type_name, cdr)
    packed = bus.pack(case.body)
    calls: dict[str, Callable[[], Any]] = {
        "build": lambda: case.build(case.body),
        "encode": lambda: ros2types.encode(case.type_name, msg),
        "decode": lambda: ros2types.decode(case.type_name, cdr),
        "convert": lambda: case.convert(decoded),
        "pack": lambda: bus.pack(case.body),
        "unpack": lambda: bus.unpack(packed),
    }
    times = {step: per_call_us(calls[step], samples, repeats) for step in STEPS}
    return {
        "message": case.name,
        "cdr_bytes": len(cdr),
        "msgpack_bytes": len(packed),
        "us": times,
        "ros2_us": round(sum(times[s]["median_us"] for s in STEPS[:4]), 2),
        "native_us": round(times["pack"]["median_us"] + times["unpack"]["median_us"], 2),
    }


def run(samples: int, repeats: int) -> dict[str, Any]:
    return {
        "bench": "cdr",
        "samples": samples,
        "repeats": repeats,
        "machine": machine(),
        "results": [measure(case, samples, repeats) for case in cases()],
    }


def print_table(result: dict[str, Any]) -> None:
    batches = f"{result['repeats']} batches of {result['samples']}"
    for figure, title in (("median_us", "median"), ("min_us", "fastest")):
        print(f"CDR per sample, µs ({title} of {batches})")
        head = " ".join(f"{s:>8}" for s in STEPS)
        print(f"{'message':<14} {'cdr B':>6} {'mp B':>6} {head} {'ros2':>8} {'native':>8}")
        for r in result["results"]:
            us = [r["us"][s][figure] for s in STEPS]
            cells = " ".join(f"{u:>8.1f}" for u in us)
            ros2, native = sum(us[:4]), us[4] + us[5]
            print(
                f"{r['message']:<14} {r['cdr_bytes']:>6} {r['msgpack_bytes']:>6} {cells} "
                f"{ros2:>8.1f} {native:>8.1f}"
            )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pnav.bench.cdr", description=__doc__)
    parser.add_argument("--samples", type=int, default=2000, help="calls per batch")
    parser.add_argument("--repeats", type=int, default=7, help="batches per figure")
    parser.add_argument("--json", metavar="PATH", help="write the figures as JSON ('-': stdout)")
    args = parser.parse_args(argv)
    if args.samples < 1 or args.repeats < 1:
        parser.error("--samples and --repeats must be at least 1")
    result = run(args.samples, args.repeats)
    print_table(result)
    emit(result, args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

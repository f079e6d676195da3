"""``pnav``: the proactive-nav command line."""

from __future__ import annotations

import argparse
import sys


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="pnav", description="proactive-nav: rule-based robot navigation"
    )
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    demo = commands.add_parser("demo", help="run the demo (see README)")
    demo.add_argument("--json", metavar="FILE", help="also write the summary as JSON")

    bench = commands.add_parser("bench", help="benchmarks: print figures and JSON")
    benches = bench.add_subparsers(dest="bench", metavar="BENCH", required=True)
    engine = benches.add_parser("engine", help="engine rules/s and wake-up latency")
    engine.add_argument("--json", metavar="FILE", help="write the figures as JSON ('-': stdout)")
    engine.add_argument("--seconds", type=float, default=3.0, help="throughput run length")
    engine.add_argument(
        "--notifications", type=int, default=1000, help="notifications for the latency run"
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.command == "bench" and args.bench == "engine":
        from pnav.bench import engine

        return engine.run(args.json, args.seconds, args.notifications)
    if args.command == "demo":
        from pnav import demo

        return demo.run(args.json)
    raise AssertionError(f"unhandled command {args.command}")  # argparse enforces the choices


if __name__ == "__main__":
    sys.exit(main())

"""``python -m pnav.monolith.versus_stack``: the same episodes in the monolith and in the stack.

    python -m pnav.monolith.versus_stack --combo GOTO_AVOID/turn_then_move \\
        worlds/barn/barn_easy_000.yaml worlds/barn/barn_hard_000.yaml

For each world (goal and time limit from its benchmark section): the episode in one process
(``run_monolith_episode``), then in the full stack (``pnav.bench.nav.stack_episode.run_episode``:
embedded Postgres, Zenoh, one process per service, sim at rate max). Printed side by side:
outcome, sim time, path length, and CPU seconds per sim second over the run proper (first
decision to the end; the stack's over every process, Postgres included), with the ratio.
Slow: each stack episode starts and stops a whole stack.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import uvloop

from pnav.bench.nav.stack_episode import Combo, Episode, run_episode
from pnav.bench.nav.worldfile import read_benchmark
from pnav.monolith.__main__ import parse_combo
from pnav.monolith.monolith_episode import run_monolith_episode
from pnav.monolith.summary import summary


def compare(episode: Episode) -> dict[str, Any]:
    mono = summary(run_monolith_episode(episode))
    stack = summary(uvloop.run(run_episode(episode)))
    ratio = None
    if mono["cpu_per_sim_s"] and stack["cpu_per_sim_s"]:
        ratio = round(stack["cpu_per_sim_s"] / mono["cpu_per_sim_s"], 1)
    return {
        "world": episode.world.stem,
        "combo": episode.combo.label,
        "monolith": mono,
        "stack": stack,
        "cpu_ratio": ratio,
    }


def row(result: dict[str, Any]) -> str:
    m, s = result["monolith"], result["stack"]
    lat = m["latency_ms"]
    return (
        f"{result['world']:<18} {result['combo']:<30} "
        f"{m['end']:>9} {s['end']:>9}  {m['time_s']:7.2f} {s['time_s']:7.2f}  "
        f"{m['path_m']:6.2f} {s['path_m']:6.2f}  {m['cpu_per_sim_s']!s:>7} "
        f"{s['cpu_per_sim_s']!s:>7} x{result['cpu_ratio']!s:<6} {lat['p50']!s:>6} {lat['p99']!s:>6}"
    )


HEADER = (
    f"{'world':<18} {'combo':<30} {'end mono':>9} {'stack':>9}  {'t mono':>7} {'stack':>7}  "
    f"{'path m':>6} {'stack':>6}  {'CPU/sim':>7} {'stack':>7} {'ratio':<7} {'lat50':>6} "
    f"{'lat99':>6}"
)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m pnav.monolith.versus_stack")
    p.add_argument("worlds", nargs="+", type=Path, help="benchmark world files")
    p.add_argument("--combo", type=parse_combo, action="append", help="repeatable")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", action="store_true", help="one JSON line per episode")
    args = p.parse_args(argv)
    combos: list[Combo] = args.combo or [Combo("GOTO_AVOID", "turn_then_move")]
    if not args.json:
        print(HEADER)
    for world in args.worlds:
        bench = read_benchmark(world)
        for combo in combos:
            episode = Episode(world, bench.goal, combo, bench.time_limit_s, seed=args.seed)
            result = compare(episode)
            print(json.dumps(result) if args.json else row(result), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

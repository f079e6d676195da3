"""``python -m pnav.monolith``: one navigation episode with the logic in one process.

    python -m pnav.monolith --world worlds/barn/barn_easy_000.yaml \\
        --combo GOTO_AVOID/turn_then_move

The goal and the time limit come from the world's ``benchmark`` section (docs/NAVBENCH.md)
unless given; ``--json`` prints the figures as JSON.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from common.errors import WorldError
from pnav.bench.nav.stack_episode import Combo, Episode
from pnav.bench.nav.worldfile import is_benchmark_world, read_benchmark
from pnav.monolith.monolith_episode import run_monolith_episode
from pnav.monolith.summary import describe, summary

DEFAULT_TIME_LIMIT_S = 120.0


def parse_combo(text: str) -> Combo:
    """``STRATEGY/planner_scenario`` (a bare strategy: turn_then_move)."""
    strategy, _, planner = text.partition("/")
    if not strategy:
        raise argparse.ArgumentTypeError(f"{text!r}: expected STRATEGY/planner_scenario")
    return Combo(strategy, planner or "turn_then_move")


def episode_from_args(args: argparse.Namespace) -> Episode:
    world = Path(args.world)
    goal, limit = args.goal, args.time_limit
    if is_benchmark_world(world):
        bench = read_benchmark(world)
        goal = goal or list(bench.goal)
        limit = limit or bench.time_limit_s
    if not goal:
        raise WorldError(f"{world}: no benchmark section: pass --goal X Y")
    return Episode(
        world=world,
        goal=(float(goal[0]), float(goal[1])),
        combo=args.combo,
        time_limit_s=limit or DEFAULT_TIME_LIMIT_S,
        seed=args.seed,
        robot=args.robot,
    )


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m pnav.monolith", description=__doc__.split("\n")[0])
    p.add_argument("--world", required=True, help="a world file (a benchmark world: its goal)")
    p.add_argument("--combo", type=parse_combo, default=Combo("GOTO_AVOID", "turn_then_move"))
    p.add_argument("--goal", type=float, nargs=2, metavar=("X", "Y"))
    p.add_argument("--time-limit", type=float, help="sim seconds (default: the world's, or 120)")
    p.add_argument("--seed", type=int, default=0, help="the sim's sensor-noise seed")
    p.add_argument("--robot", default="r1")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        episode = episode_from_args(args)
        outcome = run_monolith_episode(episode)
    except (WorldError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    figures = summary(outcome)
    if args.json:
        print(json.dumps({"world": str(episode.world), "combo": episode.combo.label, **figures}))
    else:
        print(f"{episode.world} {episode.combo.label} (monolith)")
        print(describe(figures))
    return 0


if __name__ == "__main__":
    sys.exit(main())

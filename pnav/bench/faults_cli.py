"""The ``pnav bench faults`` command line, kept light: pnav/cli/parser.py builds every parser
at each start, and the benchmark itself (pnav.bench.faults) imports the whole launcher."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any


def add_faults_parser(benches: Any, positive: Callable[[str], float]) -> None:
    """``pnav bench faults``: its options (the run is pnav.bench.faults.run)."""
    faults = benches.add_parser(
        "faults",
        help="one mission per injected fault: outcome, collisions, drift, rows lost",
        description="Runs one mission per fault (kill -9 of each service and of Postgres, "
        "router freezes, cut links, a spoofed sensor stream, a rogue recommendation, bad "
        "goals) and reports the outcome, collisions, metres driven after the last command, "
        "committed rows lost and restart times. 25-90 s per fault on 2 cores. Faults: "
        "kill-{sim,bridge,strategy,planner,controller,decision}, kill-postgres, "
        "freeze-router-3s, freeze-router-10s, cut-bridge-5s, cut-decision-5s, spoof-odom, "
        "rogue-priority, goal-nan, goal-inf, goal-1e308, tolerance-nan, tolerance-negative, "
        "goal-outside-map, goal-in-obstacle.",
    )
    faults.add_argument("--json", metavar="FILE", help="write every fault's figures as JSON")
    faults.add_argument("--only", metavar="NAME,...", help="only these faults (names below)")
    faults.add_argument("--world", default="warehouse", help="warehouse (default), cluttered_room")
    faults.add_argument("--rate", type=positive, default=2.0, help="sim rate (default 2)")

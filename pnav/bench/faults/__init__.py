"""``pnav bench faults``: one mission per fault, and what the stack made of it.

Each fault (catalogue.py) is injected into its own mission on a world with obstacles
(warehouse by default): r1 is sent across the world and, once it has driven a metre, the
fault goes in (inject.py). Per fault: the mission's outcome (reached; failed with the
goal's reason; a bad value refused at the door with exit 2), collisions (collision_event
rows during the mission, and the sim's own contact count), the most metres the robot drove
on one command after the stream stopped (measured by the sim), rows committed before the
fault and missing after it (rows.py), restart / recovery times, and for a forgery (spoofed
odometry, a forged cmd_vel) how many forged messages had an effect (stored, or applied by
the sim). Targets: every mission completes or fails safely with a reason, 0 collisions,
<= 0.15 m after the last command, 0 committed rows lost, 0 forged messages believed, no
breach (an attack that got anywhere: a lease-theft call not refused, an owner of r1 that
moved, a command citing a forged image). docs/BENCHMARKS.md ("Faults") has a run.
"""

from __future__ import annotations

import json
import logging
import os
import platform
import tempfile
import time
from pathlib import Path

import uvloop

from common.outage import fold_outage_logs
from pnav.bench.faults.bad_goals import bad_goals
from pnav.bench.faults.catalogue import mission_goal, select
from pnav.bench.faults.trial import Result, run_trial
from pnav.bench.faults.verdict import as_json, misses, table

DEFAULT_RATE = "2"


def run(
    json_path: str | None = None,
    only: str | None = None,
    world: str = "warehouse",
    rate: str = DEFAULT_RATE,
) -> int:
    """Run the faults; print the table; 0 if every target was met, 1 otherwise."""
    faults = select(only)
    # the launcher's lines (restarts) on stderr; this process's own pool, cut off by the
    # Postgres fault like the services', folds its errors into one outage line too
    logging.basicConfig(level=logging.WARNING, format="%(name)s: %(message)s")
    fold_outage_logs()
    world_path, goal = mission_goal(world)
    points = bad_goals(world_path)
    work = Path(tempfile.mkdtemp(prefix="pnav-faults-"))
    # the bench's stacks write their stack file here, not over a `pnav up` running beside
    os.environ["PNAV_STATE_DIR"] = str(work / "state")
    print(
        f"pnav bench faults: {len(faults)} fault(s), world {world_path.stem}, goal {goal}, "
        f"rate {rate}; logs in {work}",
        flush=True,
    )
    results: list[Result] = []
    for fault in faults:
        print(f"  {fault.name}: {fault.what} ...", flush=True)
        result = uvloop.run(run_trial(fault, world_path, goal, points, rate, work / fault.name))
        results.append(result)
        print(f"    {result.outcome} ({result.wall_s:.0f} s)", flush=True)
    print()
    print(table(results))
    if json_path:
        meta = {
            "bench": "faults",
            "world": world_path.stem,
            "goal": goal,
            "rate": rate,
            "machine": f"{platform.machine()}, {os.cpu_count()} cpu, {platform.python_version()}",
            "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "logs": str(work),
        }
        Path(json_path).write_text(json.dumps(as_json(results, meta), indent=2) + "\n")
    return 0 if not any(misses(r) for r in results) else 1

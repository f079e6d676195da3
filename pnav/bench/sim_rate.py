"""Benchmark: how many sim seconds per wall second the sim runs, flat out.

``python -m pnav.bench.sim_rate --robots N --seconds S [--world W]`` runs N robots for S sim
seconds with every sensor on (lidar included) and every message msgpack-encoded as it would
be for Zenoh; no Zenoh router is needed, so the figure is the simulator's own ceiling. The
robots drive circles of different radii so motion, contacts and ray casts all do real work.
It takes the sim's own options (``python -m services.sim --help``: --physics-hz, --scan-hz,
--model, ...), the world warehouse.yaml unless --world names one.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from common.bus import pack
from common.errors import UsageError
from services.sim.__main__ import build, sim_parser
from services.sim.sim import SimConfig, Simulation
from services.sim.world_spec import World

BENCH_WORLD = Path(__file__).resolve().parents[2] / "worlds" / "warehouse.yaml"

# sim seconds between two commands to a robot: the decision service's re-issue period
REISSUE_S = 0.1


@dataclass(frozen=True)
class BenchResult:
    world: str
    robots: int
    sim_seconds: float
    wall_seconds: float
    physics_hz: float
    messages: dict[str, int]
    bytes_packed: int

    @property
    def speed(self) -> float:
        """Sim seconds per wall second."""
        return self.sim_seconds / self.wall_seconds if self.wall_seconds > 0 else float("inf")

    def as_dict(self) -> dict[str, Any]:
        return {
            "bench": "sim",
            "world": self.world,
            "robots": self.robots,
            "sim_seconds": self.sim_seconds,
            "wall_seconds": round(self.wall_seconds, 4),
            "sim_per_wall": round(self.speed, 2),
            "physics_hz": self.physics_hz,
            "messages": self.messages,
            "bytes_packed": self.bytes_packed,
            "machine": {
                "cpus": os.cpu_count(),
                "processor": platform.processor() or platform.machine(),
                "python": platform.python_version(),
            },
        }


def run_bench(world: World, config: SimConfig, sim_seconds: float) -> BenchResult:
    packed = 0

    def sink(_robot: str, _topic: str, message: dict[str, Any]) -> None:
        nonlocal packed
        packed += len(pack(message))

    sim = Simulation(world, config, sink)
    # the commands are re-sent as the decision service re-issues them, so the sim's command
    # timeout never stops a robot
    reissue = max(1, round(REISSUE_S / sim.dt))
    try:
        start = time.perf_counter()
        for k in range(round(sim_seconds / sim.dt)):
            if k % reissue == 0:
                for i, robot in enumerate(sim.robots):
                    # gentle circles, a different radius each, so the robots roam the world
                    sim.set_command(robot.robot_id, 0.2, 0.3 + 0.1 * (i % 5))
            sim.step()
        wall = time.perf_counter() - start
    finally:
        sim.close()
    return BenchResult(
        world=world.name,
        robots=len(world.robots),
        sim_seconds=sim_seconds,
        wall_seconds=wall,
        physics_hz=config.physics_hz,
        messages=dict(sim.counts),
        bytes_packed=packed,
    )


def report(result: BenchResult) -> str:
    """The human line, then the JSON line."""
    line = (
        f"sim bench: {result.robots} robot(s) in {result.world}, {result.sim_seconds:g} sim s "
        f"in {result.wall_seconds:.2f} wall s = {result.speed:.1f}x real time "
        f"(physics {result.physics_hz:g} Hz, lidar on)"
    )
    return line + "\n" + json.dumps(result.as_dict())


def main(argv: Sequence[str] | None = None) -> int:
    parser = sim_parser(prog="python -m pnav.bench.sim_rate")
    parser.description = "how many sim seconds per wall second the sim runs, flat out"
    parser.add_argument(
        "--seconds", type=float, default=60.0, help="sim seconds to run (default 60)"
    )
    args = parser.parse_args(argv)
    args.world = args.world or str(BENCH_WORLD)
    try:
        world, config, _rate = build(args)
    except UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(report(run_bench(world, replace(config, gui=False), args.seconds)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

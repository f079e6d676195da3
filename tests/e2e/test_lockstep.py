"""Lockstep: the same world and seed drive the same path, point for point, also with another
process burning a core. The whole stack, as `pnav bench nav` runs an episode."""

from __future__ import annotations

import asyncio
import sys
from pathlib import Path

import pytest

from pnav.bench.nav.stack_episode import LAG, Combo, Episode, Outcome, run_episode
from pnav.bench.nav.worldfile import load_suite

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

ROOT = Path(__file__).resolve().parents[2]
# A hard world where the robot weaves between obstacles within the first seconds: paths
# that drift apart by a millimetre show at once.
WORLD = "barn_hard_004"
LIMIT_S = 12.0


def episode(pacing: str = "lockstep") -> Episode:
    (world,) = [w for w in load_suite(ROOT / "worlds" / "barn") if w.name == WORLD]
    combo = Combo("GOTO_AVOID", "turn_then_move")
    return Episode(world.world_file, world.goal, combo, LIMIT_S, seed=3, pacing=pacing)


def moved(outcome: Outcome) -> float:
    (_, x0, y0), (_, x1, y1) = outcome.trajectory[0], outcome.trajectory[-1]
    return float(((x1 - x0) ** 2 + (y1 - y0) ** 2) ** 0.5)


async def test_same_world_and_seed_give_the_same_run_quiet_or_loaded(tmp_path: Path) -> None:
    quiet = await run_episode(episode(), tmp_path / "quiet")
    burner = await asyncio.create_subprocess_exec(sys.executable, "-c", "while True: pass")
    try:
        loaded = await run_episode(episode(), tmp_path / "loaded")
    finally:
        burner.kill()
        await burner.wait()
    assert quiet.gate_timeouts == 0 and loaded.gate_timeouts == 0  # the sim never gave up
    assert quiet.end == loaded.end and quiet.time_s == loaded.time_s
    assert moved(quiet) > 0.5  # it did drive somewhere
    assert len(quiet.trajectory) > 100
    assert quiet.trajectory == loaded.trajectory  # every odometry reading, exactly
    assert quiet.collisions == loaded.collisions
    # a healthy stack re-issues its commands every 0.1 s of sim time: the sim's own command
    # timeout (0.5 s) never stopped the robot
    for run in (quiet, loaded):
        stops = [line for line in sim_log(run).splitlines() if "sim stopped" in line]
        assert stops and "cmd_timeout_stops=0" in stops[-1]


def sim_log(outcome: Outcome) -> str:
    assert outcome.log_dir
    return (Path(outcome.log_dir) / "sim.log").read_text()


def test_an_unknown_pacing_is_refused() -> None:
    with pytest.raises(ValueError, match="pacing"):
        asyncio.run(run_episode(episode("fast"), None))
    assert LAG == "lag"

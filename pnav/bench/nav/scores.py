"""Navigation metrics of one run and of many: outcome, path length, SPL, BARN score.

Formulas (docs/NAVBENCH.md), with L the world's reference path length, P the length driven,
T the run's time and v the robot's top speed:

- success: the robot came within ``goal_tolerance_m`` (0.3 m) of the goal, at or before the
  time limit, and touched nothing during the run. A collision overrides everything: a run
  with one is a "collision", even if it reached the goal. A run that did not reach the goal
  by the time limit is a "timeout"; one that ended earlier without either is "stopped".
- SPL (Anderson et al. 2018, success weighted by path length): S * L / max(L, P).
- BARN score (the BARN Challenge's metric): S * OT / clip(T, 2 OT, 8 OT) with the optimal
  time OT = L / v. A success takes 0.5 at best (at 2 OT or faster) and 0.125 at worst (8 OT
  or slower); a failure 0.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass
from typing import Any, Literal

from services.sim.robot import BURGER

Point = tuple[float, float]
Outcome = Literal["success", "collision", "timeout", "stopped"]

GOAL_TOLERANCE_M = 0.3
TOP_SPEED_MPS = BURGER.max_linear_mps
# the BARN Challenge clips the actual time to [2 OT, 8 OT] (its first edition used 4 OT)
SCORE_CLIP = (2.0, 8.0)


def path_length(points: Sequence[Point]) -> float:
    """Length of a polyline, metres."""
    return sum(math.dist(a, b) for a, b in itertools.pairwise(points))


def spl(success: bool, reference_length_m: float, driven_length_m: float) -> float:
    """Success weighted by path length for one run: S * L / max(L, P), within [0, 1]."""
    if reference_length_m <= 0:
        raise ValueError(f"the reference length must be positive, got {reference_length_m}")
    if not success:
        return 0.0
    return reference_length_m / max(reference_length_m, driven_length_m)


def optimal_time(reference_length_m: float, top_speed_mps: float = TOP_SPEED_MPS) -> float:
    """OT: the reference path driven flat out, seconds."""
    if reference_length_m <= 0 or top_speed_mps <= 0:
        raise ValueError("the reference length and the top speed must be positive")
    return reference_length_m / top_speed_mps


def barn_score(
    success: bool,
    reference_length_m: float,
    actual_time_s: float,
    *,
    top_speed_mps: float = TOP_SPEED_MPS,
    clip: tuple[float, float] = SCORE_CLIP,
) -> float:
    """S * OT / clip(T, clip[0] * OT, clip[1] * OT): 1/clip[0] at best, 1/clip[1] at worst."""
    ot = optimal_time(reference_length_m, top_speed_mps)
    if not success:
        return 0.0
    return ot / min(max(actual_time_s, clip[0] * ot), clip[1] * ot)


def default_time_limit(reference_length_m: float, top_speed_mps: float = TOP_SPEED_MPS) -> float:
    """The suggested time limit: 8 OT (past which the score no longer changes), rounded up
    to whole 10 s."""
    return 10.0 * math.ceil(SCORE_CLIP[1] * optimal_time(reference_length_m, top_speed_mps) / 10)


@dataclass(frozen=True)
class RunResult:
    """One run, scored. ``time_s`` is the time of arrival for a success, else the run's."""

    outcome: Outcome
    success: bool
    collision: bool
    timeout: bool
    time_s: float
    path_length_m: float
    final_distance_m: float  # to the goal, where the run ended (or arrived)
    reference_length_m: float
    optimal_time_s: float
    spl: float
    score: float
    collision_count: int

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (floats rounded to 4 decimals)."""
        return {k: round(v, 4) if isinstance(v, float) else v for k, v in asdict(self).items()}


def evaluate_run(
    trajectory: Sequence[Point],
    *,
    goal: Point,
    elapsed_s: float,
    time_limit_s: float,
    reference_length_m: float,
    collisions: Sequence[Point] = (),
    times: Sequence[float] | None = None,
    goal_tolerance_m: float = GOAL_TOLERANCE_M,
    top_speed_mps: float = TOP_SPEED_MPS,
) -> RunResult:
    """Score a run from the robot's positions (start first), the places it touched something,
    and the sim time it took.

    The run counts up to the first position within the tolerance: what the robot drives
    after arriving is not its path. ``times`` (sim seconds per position, optional) gives the
    time of that arrival; without it the arrival time is ``elapsed_s``, so a runner that
    stops the run on arrival needs none."""
    if not trajectory:
        raise ValueError("the trajectory needs at least the start position")
    if times is not None and len(times) != len(trajectory):
        raise ValueError("times must give one time per trajectory point")
    distances = [math.dist(p, goal) for p in trajectory]
    arrival = next((i for i, d in enumerate(distances) if d <= goal_tolerance_m), None)
    end = len(trajectory) - 1 if arrival is None else arrival
    if arrival is not None and times is not None:
        run_time = float(times[arrival])
    else:
        run_time = float(elapsed_s)
    driven = path_length(trajectory[: end + 1])
    collided = len(collisions) > 0
    in_time = run_time <= time_limit_s
    success = arrival is not None and in_time and not collided
    outcome: Outcome
    if collided:
        outcome = "collision"
    elif success:
        outcome = "success"
    elif run_time >= time_limit_s:  # arrived too late, or never
        outcome = "timeout"
    else:
        outcome = "stopped"
    return RunResult(
        outcome=outcome,
        success=success,
        collision=collided,
        timeout=outcome == "timeout",
        time_s=run_time,
        path_length_m=driven,
        final_distance_m=distances[end],
        reference_length_m=reference_length_m,
        optimal_time_s=optimal_time(reference_length_m, top_speed_mps),
        spl=spl(success, reference_length_m, driven),
        score=barn_score(success, reference_length_m, run_time, top_speed_mps=top_speed_mps),
        collision_count=len(collisions),
    )


def _mean(values: Sequence[float]) -> float | None:
    return sum(values) / len(values) if values else None


@dataclass(frozen=True)
class Summary:
    """Many runs: rates over all runs; SPL and score averaged over all runs (a failure counts
    0); time and path length averaged over all runs and over the successful ones (None when
    there is none)."""

    runs: int
    successes: int
    collisions: int
    timeouts: int
    stopped: int
    success_rate: float
    collision_rate: float
    timeout_rate: float
    mean_spl: float
    mean_score: float
    mean_time_s: float | None
    mean_path_length_m: float | None
    mean_success_time_s: float | None
    mean_success_path_length_m: float | None

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (floats rounded to 4 decimals)."""
        return {k: round(v, 4) if isinstance(v, float) else v for k, v in asdict(self).items()}


def summarize(results: Iterable[RunResult]) -> Summary:
    runs = list(results)
    if not runs:
        raise ValueError("nothing to summarize: no runs")
    n = len(runs)
    won = [r for r in runs if r.success]
    count = {o: sum(r.outcome == o for r in runs) for o in ("collision", "timeout", "stopped")}
    return Summary(
        runs=n,
        successes=len(won),
        collisions=count["collision"],
        timeouts=count["timeout"],
        stopped=count["stopped"],
        success_rate=len(won) / n,
        collision_rate=count["collision"] / n,
        timeout_rate=count["timeout"] / n,
        mean_spl=sum(r.spl for r in runs) / n,
        mean_score=sum(r.score for r in runs) / n,
        mean_time_s=_mean([r.time_s for r in runs]),
        mean_path_length_m=_mean([r.path_length_m for r in runs]),
        mean_success_time_s=_mean([r.time_s for r in won]),
        mean_success_path_length_m=_mean([r.path_length_m for r in won]),
    )


def mean_spl(results: Iterable[RunResult]) -> float:
    return summarize(results).mean_spl


def summarize_by(items: Iterable[tuple[str, RunResult]]) -> dict[str, Summary]:
    """One summary per key (a level, a world...), keys in first-seen order."""
    groups: dict[str, list[RunResult]] = {}
    for key, result in items:
        groups.setdefault(key, []).append(result)
    return {key: summarize(runs) for key, runs in groups.items()}

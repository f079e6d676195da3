"""Scoring a run by the BARN protocol, worked out by hand: OT at the model's top speed, the
score at its clip edges (2 OT and 8 OT), the 1 m success rule, BARN's time limit; and
``pnav bench nav --model``, which runs and scores a world with another robot model."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import pytest
import yaml

from pnav.bench.nav import barn, runner
from pnav.bench.nav import stack_episode as episode_module
from pnav.bench.nav.barn import generate_barn_world
from pnav.bench.nav.barnfile import write_barn_world
from pnav.bench.nav.robots import RobotFit, resolve_model
from pnav.bench.nav.scores import RunResult, barn_score, evaluate_run
from pnav.bench.nav.stack_episode import Episode, Outcome
from pnav.bench.nav.worldfile import for_model, load_suite, read_benchmark, too_big
from pnav.cli import program as cli
from services.sim.world_spec import load_world

pytestmark = pytest.mark.timeout(60)

JACKAL = resolve_model("jackal")
GOAL = (2.4, 10.7)
ROOT = Path(__file__).resolve().parents[3]
SUITE = ROOT / "worlds" / "barn"


def score(time_s: float, length_m: float = 10.0) -> float:
    return barn_score(True, length_m, time_s, top_speed_mps=2.0)


def test_score_at_the_clip_edges_with_ot_at_2_mps() -> None:
    # L = 10 m at 2 m/s: OT = 5 s, so the clip is [10 s, 40 s]
    assert score(5.0) == 0.5  # faster than 2 OT counts as 2 OT
    assert score(10.0) == 0.5  # 2 OT: the best score
    assert score(20.0) == 0.25  # 4 OT
    assert score(40.0) == 0.125  # 8 OT: the worst a success scores
    assert score(100.0) == 0.125  # slower still: no lower
    assert score(10.5) == pytest.approx(5.0 / 10.5)  # just past 2 OT
    assert barn_score(False, 10.0, 12.0, top_speed_mps=2.0) == 0.0
    # the challenge's first edition clipped at 4 OT: 0.25 at best
    assert barn_score(True, 10.0, 10.0, top_speed_mps=2.0, clip=(4.0, 8.0)) == 0.25


def run(
    end: tuple[float, float], time_s: float, collisions: Sequence[tuple[float, float]] = ()
) -> RunResult:
    return evaluate_run(
        [(2.4, 0.7), (2.4, 5.0), end],
        goal=GOAL,
        elapsed_s=time_s,
        time_limit_s=barn.BARN_TIME_LIMIT_S,
        reference_length_m=10.0,
        collisions=collisions,
        goal_tolerance_m=barn.GOAL_TOLERANCE_M,
        top_speed_mps=2.0,
    )


def test_success_within_1_m_of_the_goal() -> None:
    inside = run((2.4, GOAL[1] - 0.99), 20.0)
    assert (inside.outcome, inside.success, inside.score) == ("success", True, 0.25)
    assert inside.optimal_time_s == 5.0
    outside = run((2.4, GOAL[1] - 1.01), 20.0)  # stopped 1.01 m short, before the limit
    assert (outside.outcome, outside.success, outside.score) == ("stopped", False, 0.0)
    aside = run((2.4 + 0.9, GOAL[1] - 0.3), 20.0)  # 0.95 m away, off to the side
    assert aside.success


def test_barns_time_limit_and_collision_rules() -> None:
    assert run((2.4, GOAL[1]), 100.0).outcome == "success"  # at the limit: still in time
    late = run((2.4, GOAL[1]), 100.5)
    assert (late.outcome, late.timeout, late.score) == ("timeout", True, 0.0)
    never = run((2.4, 6.0), 100.0)
    assert never.outcome == "timeout"
    hit = run((2.4, GOAL[1]), 20.0, collisions=[(2.4, 5.0)])
    assert (hit.outcome, hit.success, hit.score) == ("collision", False, 0.0)


def test_a_world_run_with_another_model_is_scored_at_its_top_speed(tmp_path: Path) -> None:
    bench = read_benchmark(
        write_barn_world(generate_barn_world("easy", 1, JACKAL), tmp_path / "suite")
    )
    # a model of its own file: the Jackal at half its top speed
    model_file = tmp_path / "slower.yaml"
    text = (ROOT / "models" / "jackal.yaml").read_text()
    text = text.replace("name: jackal", "name: slower")
    model_file.write_text(text.replace("max_linear_mps: 2.0", "max_linear_mps: 1.0"))
    slower = resolve_model(str(model_file))
    assert (slower.name, slower.max_linear_mps, slower.world_ref) == (
        "slower",
        1.0,
        str(model_file),
    )
    moved = for_model(bench, slower, tmp_path / "worlds")
    assert (moved.top_speed_mps, moved.model) == (1.0, "slower")
    assert moved.optimal_time_s == pytest.approx(bench.reference_length_m / 1.0)
    assert moved.time_limit_s == 200.0  # BARN's 100 s at 2 m/s, at half the speed
    assert (moved.goal, moved.goal_tolerance_m) == (bench.goal, 1.0)
    # the stack runs a copy of the world whose robot is that model; same map, same obstacles
    assert moved.world_file != bench.world_file and moved.world_file.parent == tmp_path / "worlds"
    copy = yaml.safe_load(moved.world_file.read_text())
    assert [r["model"] for r in copy["robots"]] == [str(model_file)]
    original, loaded = load_world(bench.world_file), load_world(moved.world_file)
    assert loaded.obstacles == original.obstacles
    assert [r.model.max_linear_mps for r in loaded.robots] == [1.0]  # the sim builds it
    assert (loaded.grid.cells == original.grid.cells).all()
    # its own model: the world file as it is
    same = for_model(bench, JACKAL, tmp_path / "worlds")
    assert same.world_file == bench.world_file and same.time_limit_s == 100.0


def test_the_default_protocol_keeps_its_time_limit_and_warns_of_a_bigger_robot(
    tmp_path: Path,
) -> None:
    worlds = load_suite(SUITE)[:3]
    moved = for_model(worlds[0], JACKAL, tmp_path)
    assert moved.time_limit_s == worlds[0].time_limit_s  # 8 OT at the Burger's speed: generous
    assert moved.optimal_time_s == pytest.approx(worlds[0].reference_length_m / 2.0)
    # the Burger's worlds were checked for a 0.105 m disc: a Jackal may not fit
    assert too_big(worlds, JACKAL) == [w.name for w in worlds]
    assert too_big(worlds, RobotFit("tiny", 0.2, 0.1)) == []


def test_bench_nav_with_a_model_runs_a_copy_of_each_world_and_scores_at_its_speed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    seen: list[Episode] = []

    async def run_episode(episode: Episode, log_dir: Path | None = None) -> Outcome:
        seen.append(episode)  # the stack stands in: it arrives 0.9 m short of the goal
        return Outcome("goal", 20.0, [(0.0, 2.4, 0.7), (20.0, 2.4, 9.8)], [], 0.9, wall_s=1.0)

    monkeypatch.setattr(episode_module, "run_episode", run_episode)
    report_dir = tmp_path / "report"
    args = cli.build_parser().parse_args(
        [
            *("bench", "nav", "--suite", str(ROOT / "worlds" / "barn_protocol")),
            *("--levels", "easy", "--worlds", "1", "--combos", "GOTO_AVOID/turn_then_move"),
            *("--model", "turtlebot3_burger", "--in-process"),
            *("--json", str(tmp_path / "nav.json"), "--report", str(report_dir)),
        ]
    )
    assert runner.run(args) == 0
    (episode,) = seen
    assert episode.world == report_dir / "logs" / "worlds" / "barn_easy_000__turtlebot3_burger.yaml"
    assert (episode.goal, episode.goal_tolerance_m, episode.time_limit_s) == ((2.4, 10.7), 1.0, 910)
    assert load_world(episode.world).robots[0].model.name == "turtlebot3_burger"
    (run,) = json.loads((tmp_path / "nav.json").read_text())["runs"]
    ot = run["reference_length_m"] / 0.22
    assert run["optimal_time_s"] == pytest.approx(ot, abs=1e-3)
    assert (run["outcome"], run["score"]) == ("success", 0.5)  # 20 s is under 2 OT (91 s)
    readme = (report_dir / "README.md").read_text()
    assert "within the goal tolerance (1 m)" in readme and "`turtlebot3_burger`" in readme
    assert "warning" not in capsys.readouterr().err  # the Burger fits where the Jackal does

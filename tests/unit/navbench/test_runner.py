"""``pnav bench nav`` without the stack: which combos ship, scoring an episode's outcome, the
progress bar, and what the bench prints and writes, with made-up episodes standing in for
the stack (and for the monolith)."""

from __future__ import annotations

import io
import json
import math
import sys
import types
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from common import bus
from common.contract.migrate import schema_text
from common.errors import UsageError
from pnav.bench.nav import nav_report, progress, run_diff, runner
from pnav.bench.nav import stack_episode as episode_module
from pnav.bench.nav.stack_episode import Combo, Episode, Outcome
from pnav.bench.nav.worldfile import BenchmarkWorld, load_suite
from pnav.cli import program as cli
from services.planner.meta import move_scenarios

pytestmark = pytest.mark.timeout(60)
SCENARIOS = move_scenarios()  # the planner's move scenarios, as installed (entry points)

SUITE = Path(__file__).resolve().parents[3] / "worlds" / "barn"
AVOID = Combo("GOTO_AVOID", "turn_then_move")
DIRECT = Combo("GOTO_DIRECT", "move_while_turning")


@pytest.fixture(scope="module")
def suite() -> list[BenchmarkWorld]:
    return load_suite(SUITE)


Path3 = list[tuple[float, float, float]]


def drive(world: BenchmarkWorld, *, to: float = 1.0, speed: float = 0.2, hz: float = 10.0) -> Path3:
    """(t, x, y) along the reference path, at ``speed``, up to fraction ``to`` of it."""
    points: Path3 = [(0.0, *world.reference_path[0])]
    t = 0.0
    for (x0, y0), (x1, y1) in zip(world.reference_path, world.reference_path[1:], strict=False):
        n = max(1, math.ceil(math.dist((x0, y0), (x1, y1)) / (speed / hz)))
        for i in range(1, n + 1):
            t += math.dist((x0, y0), (x1, y1)) / n / speed
            points.append((t, x0 + (x1 - x0) * i / n, y0 + (y1 - y0) * i / n))
    return points[: max(1, round(len(points) * to))]


# --- which combos ship ----------------------------------------------------------------------


def test_the_goal_strategies_of_the_contract_times_the_registered_planners() -> None:
    goal_strategies = ["GOTO_AVOID", "GOTO_DIRECT", "GOTO_FAST", "GOTO_DODGE"]
    assert runner.navigation_strategies(schema_text()) == goal_strategies
    combos = runner.shipped_combos()
    assert [c.label for c in combos] == [f"{s}/{p}" for s in goal_strategies for p in SCENARIOS]
    assert set(SCENARIOS) == {"turn_then_move", "move_while_turning"}


def test_a_strategy_counts_when_its_params_target_the_goal() -> None:
    sql = """
    INSERT INTO strategy (code, planner_scenario, controller_scenarios, params, description) VALUES
        ('FAST', 'turn_then_move', '{safety_stop}', '{"target": "goal"}', 'fast'),
        ('HOME', 'turn_then_move', '{}', '{"target": "nearest_charger",
          "x": 1}', 'charge'),
        ('IDLE', NULL, '{}', '{}', 'stand still');
    INSERT INTO goal (robot_id) VALUES ('r1');
    -- migration 9: a later one adds a strategy
    INSERT INTO strategy (code, planner_scenario, controller_scenarios, params) VALUES
        ('SLOW', 'move_while_turning', '{}', '{"target": "goal", "speed": 0.1}');
    """
    assert runner.navigation_strategies(sql) == ["FAST", "SLOW"]


def test_combos_are_picked_by_label_strategy_or_planner() -> None:
    shipped = runner.shipped_combos()
    assert runner.pick_combos(None, shipped) == shipped
    assert runner.pick_combos("goto_avoid/TURN_THEN_MOVE", shipped) == [AVOID]
    assert [c.planner for c in runner.pick_combos("GOTO_DIRECT", shipped)] == list(SCENARIOS)
    both = runner.pick_combos("move_while_turning, GOTO_DIRECT/move_while_turning", shipped)
    assert [c.label for c in both] == [
        "GOTO_AVOID/move_while_turning",
        DIRECT.label,
        "GOTO_FAST/move_while_turning",
        "GOTO_DODGE/move_while_turning",
    ]
    with pytest.raises(UsageError, match="GOTO_AVOID/turn_then_move"):
        runner.pick_combos("GOTO_AVOID/teleport", shipped)


def test_worlds_are_picked_per_level_by_count_or_by_name(suite: list[BenchmarkWorld]) -> None:
    names = [w.name for w in runner.select_worlds(suite, None, "2")]
    assert names == [f"barn_{lv}_{i:03d}" for lv in ("easy", "medium", "hard") for i in (0, 1)]
    assert [w.name for w in runner.select_worlds(suite, "easy", "1")] == ["barn_easy_000"]
    assert len(runner.select_worlds(suite, "medium,hard", None)) == 40
    picked = runner.select_worlds(suite, None, "barn_hard_003,barn_easy_007")
    assert [w.name for w in picked] == ["barn_easy_007", "barn_hard_003"]  # suite order
    for levels, pick in (("expert", None), (None, "0"), ("easy", "barn_hard_003"), (None, ",")):
        with pytest.raises(UsageError):
            runner.select_worlds(suite, levels, pick)


# --- an episode's outcome, scored ---------------------------------------------------------


def test_a_run_to_the_goal_is_scored_against_the_world(suite: list[BenchmarkWorld]) -> None:
    world = suite[0]
    path = drive(world)
    arrival = next(p for p in path if math.dist(p[1:], world.goal) <= 0.3)
    outcome = Outcome("goal", arrival[0], path, [], 0.3, wall_s=6.0, run_wall_s=3.5, cpu_s=4.0)
    rec = runner.to_record(world, AVOID, 0, "stack", outcome)
    r = rec.result
    assert (r.outcome, rec.end, rec.combo, rec.level) == ("success", "goal", AVOID.label, "easy")
    assert r.time_s == pytest.approx(arrival[0])
    # driven up to the arrival only, along the reference path: shorter than it, SPL 1
    assert r.path_length_m == pytest.approx(world.reference_length_m - 0.3, abs=0.03)
    assert r.spl == 1.0
    assert r.optimal_time_s == pytest.approx(world.reference_length_m / world.top_speed_mps)
    assert r.score == pytest.approx(r.optimal_time_s / max(r.time_s, 2 * r.optimal_time_s))
    assert (rec.run_wall_s, rec.cpu_s, rec.wall_s) == (3.5, 4.0, 6.0)


def test_a_stalled_run_is_a_failure_that_says_why(suite: list[BenchmarkWorld]) -> None:
    world = suite[0]
    path = drive(world, to=0.4)
    rec = runner.to_record(world, AVOID, 0, "stack", Outcome("stalled", path[-1][0], path))
    assert (rec.result.outcome, rec.end, rec.result.success, rec.result.spl) == (
        "stopped",
        "stalled",
        False,
        0.0,
    )
    assert any("stalled" in line for line in nav_report.attention([rec]))


def test_collisions_and_timeouts(suite: list[BenchmarkWorld]) -> None:
    world = suite[0]
    path = drive(world)
    hit = Outcome("collision", 5.0, path[:20], [(5.0, *path[19][1:], "wall")])
    rec = runner.to_record(world, AVOID, 0, "stack", hit)
    assert (rec.result.outcome, rec.result.collision_count, rec.result.score) == (
        "collision",
        1,
        0.0,
    )
    late = runner.to_record(
        world, AVOID, 0, "stack", Outcome("timeout", world.time_limit_s, path[:30])
    )
    assert late.result.outcome == "timeout" and late.result.timeout


def test_a_run_that_never_started_is_scored_from_the_start(suite: list[BenchmarkWorld]) -> None:
    rec = runner.to_record(suite[0], AVOID, 2, "stack", Outcome("error", 0.0))
    assert (rec.result.outcome, rec.result.path_length_m, rec.seed) == ("stopped", 0.0, 2)


@dataclass
class MonolithOutcome:  # the shape pnav.monolith promises: Outcome's fields, cpu_s, latency
    end: str
    time_s: float
    trajectory: list[tuple[float, float, float]] = field(default_factory=list)
    collisions: list[tuple[float, float, float, str]] = field(default_factory=list)
    final_distance_m: float = math.inf
    wall_s: float = 0.0
    cpu_s: float = 0.0
    latency_ms: list[float] = field(default_factory=list)


def test_a_monolith_outcome_scores_the_same_way(suite: list[BenchmarkWorld]) -> None:
    path = drive(suite[0])
    mono = MonolithOutcome("goal", path[-1][0], path, wall_s=2.0, cpu_s=1.5, latency_ms=[1, 2])
    rec = runner.to_record(suite[0], AVOID, 0, "monolith", mono)  # type: ignore[arg-type]
    assert (rec.result.outcome, rec.run_wall_s, rec.cpu_s, rec.latency_ms) == (
        "success",
        2.0,  # no start-up to leave out
        1.5,
        [1, 2],
    )
    assert rec.gate_timeouts is None


# --- progress -------------------------------------------------------------------------------


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_redraws_in_place_on_a_terminal_and_writes_lines_elsewhere() -> None:
    term, out = Terminal(), io.StringIO()
    bar = progress.Progress(4, term, out)
    bar.begin("barn_easy_000 GOTO_AVOID/turn_then_move run 0 stack")
    assert "\r[....................] 0/4 barn_easy_000" in term.getvalue()
    assert "ETA --" in term.getvalue() and "\n" not in term.getvalue()
    bar.finish("barn_easy_000: success")
    assert out.getvalue() == "barn_easy_000: success\n"
    assert "1/4" in bar.line() and "#####" in bar.line() and "ETA 0m0" in bar.line()
    log = io.StringIO()
    plain = progress.Progress(2, log, io.StringIO())
    plain.begin("a")
    plain.finish("done a")
    plain.begin("b")
    assert "\r" not in log.getvalue() and log.getvalue().count("\n") == 2
    plain.finish("done b")
    plain.close()
    assert log.getvalue().splitlines()[-1].startswith("[####################] 2/2 done")
    bar.close()
    last = term.getvalue().split("\r")[-1]  # the bar's final state, then a new line
    assert last.startswith("[#####...............] 1/4 done") and last.endswith(" \n")
    assert progress.clock(3725) == "1h02m" and progress.clock(65) == "1m05s"


# --- the whole bench, with made-up episodes ---------------------------------------------------


def fake_stack(suite: list[BenchmarkWorld]) -> Callable[..., Awaitable[Outcome]]:
    """run_episode's stand-in: GOTO_AVOID reaches the goal, GOTO_DIRECT hits something in
    the hard worlds and stalls half-way in the others."""
    worlds = {w.world_file: w for w in suite}

    async def run_episode(episode: Episode, log_dir: Path | None = None) -> Outcome:
        world = worlds[episode.world]
        path = drive(world)
        if episode.combo.strategy == "GOTO_DIRECT":
            if world.level == "hard":
                return Outcome("collision", 10.0, path[:50], [(10.0, *path[49][1:], "w")])
            return Outcome("stalled", 12.0, path[: len(path) // 2], wall_s=9.0)
        arrival = next(p for p in path if math.dist(p[1:], world.goal) <= 0.3)
        return Outcome(
            *("goal", arrival[0], path, [], 0.3),
            **dict(wall_s=5.0, run_wall_s=2.0, cpu_s=3.0, gate_waits_per_sim_s=60.0),
            cpu_by_role={"sim": 2.0, "bridge": 0.75, "postgres": 0.25},
        )

    return run_episode


def bench(tmp_path: Path, *extra: str) -> tuple[int, dict[str, Any], str]:
    args = cli.build_parser().parse_args(
        [
            *("bench", "nav", "--suite", str(SUITE), "--worlds", "1", "--levels", "easy,hard"),
            *("--combos", "GOTO_AVOID/turn_then_move,GOTO_DIRECT/move_while_turning"),
            *("--json", str(tmp_path / "nav.json"), "--report", str(tmp_path / "report")),
            "--in-process",  # the fake episodes are patched into this process
            *extra,
        ]
    )
    code = runner.run(args)
    readme = (tmp_path / "report" / "README.md").read_text()
    return code, json.loads((tmp_path / "nav.json").read_text()), readme


def test_the_bench_writes_json_a_picture_per_run_and_a_readme(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    suite: list[BenchmarkWorld],
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.setattr(episode_module, "run_episode", fake_stack(suite))
    code, doc, readme = bench(tmp_path)
    assert code == 0
    runs = doc["runs"]
    assert [(r["world"], r["combo"], r["outcome"], r["end"]) for r in runs] == [
        ("barn_easy_000", AVOID.label, "success", "goal"),
        ("barn_easy_000", DIRECT.label, "stopped", "stalled"),
        ("barn_hard_000", AVOID.label, "success", "goal"),
        ("barn_hard_000", DIRECT.label, "collision", "collision"),
    ]
    by_combo = doc["summary"]["stack"]["by_combo"]
    assert by_combo[AVOID.label]["success_rate"] == 1.0
    assert by_combo[DIRECT.label]["collision_rate"] == 0.5
    assert by_combo[DIRECT.label]["stopped"] == 1
    assert doc["summary"]["stack"]["by_combo_level"][DIRECT.label]["hard"]["collisions"] == 1
    # pooled over the combo's runs: CPU seconds over sim seconds, 3 s of CPU each
    assert doc["cost"][AVOID.label]["stack"]["cpu_per_sim_s"] == pytest.approx(
        6.0 / (runs[0]["time_s"] + runs[2]["time_s"]), rel=1e-3
    )
    assert doc["machine"]["cpus"] >= 1 and "pnav bench nav" in doc["command"]
    for r in runs:  # every run linked from the README, its picture a PNG
        png = tmp_path / "report" / r["png"]
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert f"[{r['png']}]({r['png']})" in readme
    assert runs[0]["png"] == "barn_easy_000__GOTO_AVOID-turn_then_move.png"
    assert "barn_easy_000 GOTO_DIRECT/move_while_turning run 0 (stack): stalled" in readme
    assert "| easy | GOTO_AVOID/turn_then_move | 1 | 100 % |" in readme
    # where it went: each role's CPU per sim second, most first, and the pacing's waits
    sim_s = runs[0]["time_s"] + runs[2]["time_s"]
    avoid = doc["cost"][AVOID.label]["stack"]
    cpu_s = {"sim": 2.0, "bridge": 0.75, "postgres": 0.25}  # a run, in the fake
    assert avoid["cpu_ms_per_sim_s_by_role"] == {
        role: pytest.approx(2 * 1000.0 * s / sim_s, abs=0.05) for role, s in cpu_s.items()
    }
    assert avoid["gate_waits_per_sim_s"] == 60.0
    # the runs that measured no process (GOTO_DIRECT's here) have no breakdown
    direct = doc["cost"][DIRECT.label]["stack"]
    assert direct["cpu_ms_per_sim_s_by_role"] == {} and direct["gate_waits_per_sim_s"] is None
    printed = capsys.readouterr().out
    assert "stack: per combo" in printed and "what the runs cost" in printed
    assert "where the stack's CPU goes, ms per sim second" in printed
    assert "where the stack's CPU goes" in readme
    lines = printed.splitlines()
    at = lines.index("where the stack's CPU goes, ms per sim second")
    assert lines[at + 1].split()[:4] == ["combo", "sim", "bridge", "postgres"]  # most first
    row = lines[at + 2].split()
    assert row[0] == AVOID.label and row[-2:] == ["-", "60.0"]  # no monolith; 60 waits a sim s
    assert float(row[4]) == pytest.approx(6000.0 / sim_s, abs=0.1)  # the stack: 3 CPU s a run


def test_the_monolith_runs_each_episode_too_and_the_costs_are_compared(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, suite: list[BenchmarkWorld]
) -> None:
    monkeypatch.setattr(episode_module, "run_episode", fake_stack(suite))

    def run_monolith_episode(episode: Episode) -> MonolithOutcome:
        world = next(w for w in suite if w.world_file == episode.world)
        path = drive(world)
        arrival = next(p for p in path if math.dist(p[1:], world.goal) <= 0.3)
        return MonolithOutcome("goal", arrival[0], path, wall_s=0.5, cpu_s=0.5, latency_ms=[0.2])

    fake = types.ModuleType("pnav.monolith")
    fake.run_monolith_episode = run_monolith_episode  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "pnav.monolith", fake)
    code, doc, readme = bench(tmp_path, "--monolith")
    assert code == 0 and len(doc["runs"]) == 8
    assert [r["mode"] for r in doc["runs"][:2]] == ["stack", "monolith"]
    ratio = doc["cost"][AVOID.label]["ratio"]
    assert ratio["cpu_per_sim_s"] == pytest.approx(6.0, rel=1e-3)  # 3.0 s against 0.5 s
    assert ratio["wall_per_sim_s"] == pytest.approx(4.0, rel=1e-3)  # 2.0 s against 0.5 s
    assert "stack / monolith" in readme and "| 100 % / 100 % |" in readme
    assert "barn_easy_000__GOTO_AVOID-turn_then_move__monolith.png" in readme


def test_without_the_monolith_the_option_says_so(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "pnav.monolith", None)  # import fails
    with pytest.raises(UsageError, match=r"--monolith needs pnav\.monolith"):
        bench(tmp_path, "--monolith")
    assert cli.main(["bench", "nav", "--suite", str(SUITE), "--monolith"]) == 2


def test_compare_finds_the_runs_that_changed(suite: list[BenchmarkWorld]) -> None:
    world = suite[0]
    path = drive(world)
    now = [
        runner.to_record(world, AVOID, 0, "stack", Outcome("goal", 30.0, path)),
        runner.to_record(world, DIRECT, 0, "stack", Outcome("stalled", 9.0, path[:40])),
    ]
    before = [r.to_json() for r in now]
    assert run_diff.compare(now, before)[-1] == (
        "2 of 2 runs with the same outcome, 2 on the same path; largest time change 0.000 s"
    )
    assert "the same path, point for point" in run_diff.compare(now, before)[0]
    arrival = now[0].result.time_s
    before[0]["time_s"] = arrival - 0.5
    before[0]["trajectory"] = [[t, x + 0.1, y] for t, x, y in before[0]["trajectory"]]
    before[1]["outcome"] = "success"
    lines = run_diff.compare(now, before)
    assert f"time {arrival - 0.5:.3f} -> {round(arrival, 4):.3f} s (+0.500)" in lines[0]
    assert "DIFFERENT" not in lines[0]

    def apart(line: str) -> float:
        return float(line.split("paths at most ")[1].split(" m")[0])

    assert 0.099 <= apart(lines[0]) < 0.11  # moved 0.1 m sideways (a bit more at an end)
    assert "DIFFERENT" in lines[1] and "the same path, point for point" in lines[1]
    assert lines[-1] == (
        "1 of 2 runs with the same outcome, 1 on the same path; largest time change 0.500 s"
    )
    assert run_diff.parted_m([], [[0.0, 1.0, 1.0]]) != run_diff.parted_m([], [])  # both NaN


# --- the episode's own pure parts -----------------------------------------------------------


def test_the_watcher_ends_a_run_at_the_first_point_inside_the_tolerance() -> None:
    watcher = episode_module.Watcher("r1", (0.0, 1.0), tolerance_m=0.3)
    assert watcher.verdict(60.0) is None  # nothing decided yet
    watcher.on_cmd_vel("k", bus.pack({"linear": 0.0, "angular": 0.0, "decided_stamp": 1.0}))
    watcher.on_cmd_vel("k", bus.pack({"linear": 0.2, "angular": 0.0, "decided_stamp": 2.0}))
    assert watcher.first_decision == 2.0  # a stop is not a start
    for i in range(40):  # 0.2 m/s from y = 0 at t = 2, 10 points a second
        watcher.on_odom("k", bus.pack({"stamp": 2.0 + i / 10, "x": 0.0, "y": 0.02 * i}))
    # many points inside the tolerance arrived since the last look: the first one counts
    end, at = watcher.verdict(60.0) or ("", 0.0)
    assert end == "goal" and at == pytest.approx(3.5)
    late = episode_module.Watcher("r1", (9.0, 9.0))
    late.first_decision = 0.0
    late.odom = [(t, 0.0, 0.0) for t in (0.0, 30.0, 60.5)]
    assert late.verdict(60.0) == ("timeout", 60.0)
    late.on_collision("k", bus.pack({"stamp": 20.0, "x": 0.1, "y": 0.2, "other": "wall"}))
    assert late.verdict(60.0) == ("collision", 20.0)  # before anything else


def test_gate_figures_come_from_the_sims_last_stop_line(tmp_path: Path) -> None:
    log = tmp_path / "sim.log"
    assert episode_module.gate_figures(log) == {}
    log.write_text(
        "x INFO sim sim stopped sim_time=1.0 gate_waits=3 gate_timeouts=1\n"
        "x INFO sim sim stopped sim_time=36.6 commands=360 gate_waits=362 gate_timeouts=0 "
        "gate_waited_wall_s=2.27\n"
    )
    assert episode_module.gate_figures(log) == {
        "gate_waits": 362,
        "gate_timeouts": 0,
        "gate_waits_per_sim_s": 9.89,  # over the last line's sim time: 362 / 36.6
    }


def test_a_lockstep_sims_timeouts_and_lost_messages_both_count_as_gate_timeouts(
    tmp_path: Path,
) -> None:
    log = tmp_path / "sim.log"
    log.write_text(
        "x INFO sim sim stopped sim_time=12.7 commands=132 lockstep_waits=847 "
        "lockstep_timeouts=1 lockstep_lost=2 lockstep_missed_at_start=7 "
        "lockstep_waited_wall_s=3.418\n"
    )
    # messages missed while the stack started (before the run) do not count
    assert episode_module.gate_figures(log) == {
        "gate_waits": 847,
        "gate_timeouts": 3,
        "gate_waits_per_sim_s": 66.69,
    }


def test_a_strategy_running_a_learned_model_is_no_shipped_combo() -> None:
    sql = """
    INSERT INTO strategy (code, planner_scenario, controller_scenarios, params) VALUES
        ('PLAIN', 'turn_then_move', '{dwa}', '{"target": "goal"}'),
        ('LEARNED', 'turn_then_move', '{learned_drive}',
         '{"target": "goal", "learned_model": "m.json"}'),
        ('FORESEEN', 'turn_then_move', '{dwa,foresight}',
         '{"target": "goal", "foresight_model": "f.json"}');
    """
    assert runner.navigation_strategies(sql) == ["PLAIN"]
    assert runner.navigation_strategies(sql, learned=True) == ["LEARNED", "FORESEEN"]


def test_a_learned_strategy_is_picked_only_by_its_name() -> None:
    shipped, learned = runner.shipped_combos(), runner.shipped_combos(learned=True)
    assert [c.label for c in learned] == [
        f"{s}/{p}" for s in ("GOTO_LEARNED", "GOTO_FORESIGHT") for p in SCENARIOS
    ]
    picked = runner.pick_combos("GOTO_LEARNED/turn_then_move", shipped, learned)
    assert [c.label for c in picked] == ["GOTO_LEARNED/turn_then_move"]
    by_planner = runner.pick_combos("turn_then_move", shipped, learned)
    assert "GOTO_LEARNED/turn_then_move" not in [c.label for c in by_planner]

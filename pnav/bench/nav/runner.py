"""``pnav bench nav``: every shipped strategy/planner combination in every world of a suite.

For each world (suite order), combo and run k (seed k) it runs the whole stack once
(``pnav.bench.nav.stack_episode``) and scores the run (``pnav.bench.nav.scores``); with
``--monolith`` it runs the same episode in the monolith right after, so both ways share the
machine's state of the moment. A progress bar on stderr meanwhile; then the summary tables
on stdout, JSON with ``--json``, pictures and a README with ``--report``
(``pnav.bench.nav.nav_report``).

The combos are read from what ships, not listed here: the contract's strategies whose params
target the goal (``schema.sql``) times the planner scenarios the planner registers.
"""

from __future__ import annotations

import argparse
import asyncio
import datetime
import importlib
import inspect
import itertools
import json
import re
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from common.errors import UsageError
from pnav.bench.nav.progress import Progress

if TYPE_CHECKING:
    # the stack (Zenoh, pybullet, numpy...) is imported when a bench runs, not with pnav's
    # parser: pnav imports this module lazily, and the tests import it without a stack
    from pnav.bench.nav.nav_report import RunRecord
    from pnav.bench.nav.robots import RobotFit
    from pnav.bench.nav.stack_episode import Combo, Episode, Outcome
    from pnav.bench.nav.workers import EpisodeWorkers
    from pnav.bench.nav.worldfile import BenchmarkWorld

STACK, MONOLITH = "stack", "monolith"  # the records' modes (pnav.bench.nav.nav_report)
# a row of the contract's INSERT INTO strategy: code, planner, controllers, params, ...
# the params that name a learned scenario's model (docs/LEARNING.md)
LEARNED_PARAMS = ("learned_model", "foresight_model")
_ROW = re.compile(r"\(\s*'([A-Z0-9_]+)'\s*,\s*(?:NULL|'[^']*')\s*,\s*'[^']*'\s*,\s*'([^']*)'")


def navigation_strategies(sql: str, learned: bool = False) -> list[str]:
    """Codes of the strategy rows ``sql`` inserts whose params target the goal, in order:
    those drive to a goal a benchmark can give (CHARGE drives to a charger, IDLE nowhere).
    A strategy that runs a learned model (``learned_model``, ``foresight_model``) is left
    out: the model file is
    trained from runs like these, so it is no shipped combo (docs/LEARNING.md); ``learned``:
    only those."""
    codes = []
    for insert in re.finditer(r"INSERT INTO strategy\b(.*?);", sql, re.S | re.I):
        for code, params in _ROW.findall(insert[1]):
            doc = json.loads(params)
            runs_model = any(key in doc for key in LEARNED_PARAMS)
            if doc.get("target") == "goal" and runs_model == learned:
                codes.append(code)
    return codes


def shipped_combos(learned: bool = False) -> list[Combo]:
    from common.contract.migrate import schema_text
    from pnav.bench.nav.stack_episode import Combo
    from services.planner.meta import move_scenarios  # installed, the planner's own first

    planners = list(move_scenarios())
    codes = navigation_strategies(schema_text(), learned)
    return [Combo(s, p) for s in codes for p in planners]


def pick_combos(
    spec: str | None, available: Sequence[Combo], named_only: Sequence[Combo] = ()
) -> list[Combo]:
    """``--combos``: comma-separated labels (``GOTO_AVOID/turn_then_move``), or a strategy
    or a planner alone for all of its combos; case-insensitive. Empty: all ``available``.
    ``named_only`` (the learned strategies' combos) are picked by label or strategy only."""
    picked: list[Combo] = []
    for token in (t.strip().lower() for t in (spec or "").split(",") if t.strip()):
        found = [c for c in available if token in (c.label.lower(), c.strategy.lower(), c.planner)]
        found += [c for c in named_only if token in (c.label.lower(), c.strategy.lower())]
        if not found:
            names = ", ".join(c.label for c in available)
            raise UsageError(f"--combos: no combo {token!r}; the shipped ones are {names}")
        picked += [c for c in found if c not in picked]
    return picked or list(available)


def select_worlds(
    worlds: Sequence[BenchmarkWorld], levels: str | None, pick: str | None
) -> list[BenchmarkWorld]:
    """``--levels easy,hard`` keeps those levels; then ``--worlds N`` the first N worlds of
    each level, ``--worlds NAME,NAME`` those worlds. Suite order throughout."""
    chosen = list(worlds)
    wanted = [lv.strip() for lv in (levels or "").split(",") if lv.strip()]
    known = list(dict.fromkeys(w.level for w in worlds))
    if levels is not None and (not wanted or set(wanted) - set(known)):
        raise UsageError(f"--levels {levels!r}: the suite's levels are {', '.join(known)}")
    chosen = [w for w in chosen if not wanted or w.level in wanted]
    if pick is not None and pick.strip().isdigit():
        if int(pick) < 1:
            raise UsageError("--worlds N: N must be 1 or more")
        rank = {w.name: [v.level for v in chosen[:i]].count(w.level) for i, w in enumerate(chosen)}
        chosen = [w for w in chosen if rank[w.name] < int(pick)]
    elif pick is not None:
        names = [n.strip() for n in pick.split(",") if n.strip()]
        missing = sorted(set(names) - {w.name for w in chosen})
        if missing or not names:
            raise UsageError(f"--worlds: not in the suite (or the levels kept): {missing}")
        chosen = [w for w in chosen if w.name in names]
    return chosen


EXTRAS = (
    *("run_wall_s", "cpu_s", "cpu_by_role", "gate_timeouts", "gate_waits_per_sim_s"),
    *("latency_ms", "log_dir"),
)


def to_record(
    world: BenchmarkWorld, combo: Combo, run: int, mode: str, outcome: Outcome
) -> RunRecord:
    """Score an episode against its world (goal, tolerance, limit, reference length, top
    speed). ``outcome`` is the stack's Outcome or the monolith's (same fields, fewer
    extras). One that never moved is scored from the start alone: a failure."""
    from pnav.bench.nav.nav_report import RunRecord
    from pnav.bench.nav.scores import evaluate_run

    trajectory = list(outcome.trajectory) or [(0.0, world.start[0], world.start[1])]
    result = evaluate_run(
        [(x, y) for _, x, y in trajectory],
        times=[t for t, _, _ in trajectory],
        goal=world.goal,
        elapsed_s=outcome.time_s,
        time_limit_s=world.time_limit_s,
        reference_length_m=world.reference_length_m,
        collisions=[(x, y) for _, x, y, _ in outcome.collisions],
        goal_tolerance_m=world.goal_tolerance_m,
        top_speed_mps=world.top_speed_mps,
    )
    # the stack's Outcome has them all; the monolith's lacks some (no start-up to leave out
    # of its wall time, no gate, no logs) and adds its latency samples
    extras = {k: getattr(outcome, k) for k in EXTRAS if hasattr(outcome, k)}
    return RunRecord(
        *(world.name, world.level, combo.label, run, run, mode, outcome.end, result),
        trajectory=list(outcome.trajectory),
        collisions=list(outcome.collisions),
        **{"wall_s": outcome.wall_s, "run_wall_s": outcome.wall_s, **extras},
    )


@dataclass
class Plan:
    worlds: list[BenchmarkWorld]
    combos: list[Combo]
    runs: int
    logs: Path
    report: Path | None = None
    monolith: Callable[[Episode], Any] | None = None
    workers: EpisodeWorkers | None = None  # None: stack episodes in this process
    pacing: str = "lockstep"  # or "lag" (pnav.bench.nav.stack_episode)
    keep_db: Path | None = None  # keep each stack episode's database in a folder here


async def attempt(plan: Plan, mode: str, episode: Episode, log_dir: Path) -> Outcome | str:
    """The episode's outcome, or the error that kept it from running: the bench goes on,
    one broken run must not cost the other 239."""
    from pnav.bench.nav.stack_episode import run_episode

    try:
        if plan.monolith is None or mode == STACK:
            if plan.workers is not None:
                return await plan.workers.run(episode, log_dir)
            return await run_episode(episode, log_dir)
        # the monolith's outcome has the Outcome's fields (and more); sync or async, it
        # must not block the event loop that draws the progress bar
        if inspect.iscoroutinefunction(plan.monolith):
            outcome: Outcome = await plan.monolith(episode)
        else:
            outcome = await asyncio.to_thread(plan.monolith, episode)
        return outcome
    except UsageError:
        raise  # a bad world or option is the same for every run: stop now
    except Exception as exc:
        return f"{type(exc).__name__}: {exc}"


async def run_one(plan: Plan, world: BenchmarkWorld, combo: Combo, k: int, mode: str) -> RunRecord:
    """One episode one way, scored, and its picture when there is a report folder."""
    from pnav.bench.nav.render import render_run
    from pnav.bench.nav.stack_episode import Episode, Outcome

    tolerance = world.goal_tolerance_m
    episode = Episode(
        world.world_file, world.goal, combo, world.time_limit_s, k, "r1", tolerance, plan.pacing
    )
    name = f"{world.name}__{combo.strategy}-{combo.planner}"
    if plan.keep_db is not None and mode == STACK:
        keep = plan.keep_db / f"{name}__{k}"
        plan.keep_db.mkdir(parents=True, exist_ok=True)
        episode = replace(episode, keep_db=str(keep))
    got = await attempt(plan, mode, episode, plan.logs / f"{name}__{k}")
    rec = to_record(world, combo, k, mode, Outcome("error", 0.0) if isinstance(got, str) else got)
    rec.error = got if isinstance(got, str) else ""
    if plan.report is not None:
        rec.png = (
            name + (f"__run{k}" if k else "") + ("" if mode == STACK else f"__{mode}") + ".png"
        )
        points = [(x, y) for _, x, y in rec.trajectory]
        hits = [(x, y) for _, x, y, _ in rec.collisions]
        render_run(plan.report / rec.png, world, trajectory=points, collisions=hits)
    return rec


async def execute(plan: Plan, progress: Progress, records: list[RunRecord]) -> None:
    """Every world, in suite order, with every combo, every run, each way, into
    ``records`` as they finish (so that an interrupted bench still has them)."""
    modes = (STACK, MONOLITH) if plan.monolith else (STACK,)
    ticker = asyncio.create_task(progress.tick())
    try:
        for world, combo, k, mode in itertools.product(
            plan.worlds, plan.combos, range(plan.runs), modes
        ):
            what = f"{world.name} {combo.label} run {k} {mode}"
            progress.begin(what)
            rec = await run_one(plan, world, combo, k, mode)
            records.append(rec)
            r = rec.result
            progress.finish(
                f"{what}: {r.outcome} ({rec.end}) {r.time_s:.1f} s sim, {rec.wall_s:.1f} s wall,"
                f" SPL {r.spl:.3f}" + (f"  [{rec.error}]" if rec.error else "")
            )
    finally:
        ticker.cancel()


def load_monolith() -> Callable[[Episode], Any]:
    """``pnav.monolith.run_monolith_episode``, imported only when ``--monolith`` asks."""
    try:
        module = importlib.import_module("pnav.monolith")
        function: Callable[[Episode], Any] = module.run_monolith_episode
    except (ImportError, AttributeError) as exc:
        raise UsageError(
            f"--monolith needs pnav.monolith.run_monolith_episode, which cannot be imported"
            f" ({exc}); run without --monolith"
        ) from None
    return function


def with_model(
    worlds: list[BenchmarkWorld], robot: RobotFit | None, folder: Path
) -> list[BenchmarkWorld]:
    """``--model NAME``: every world run and scored with that robot model
    (``pnav.bench.nav.worldfile.for_model``); None: each world with its own."""
    if robot is None:
        return worlds
    from pnav.bench.nav.worldfile import for_model, too_big

    tight = too_big(worlds, robot)
    if tight:
        print(
            f"warning: {len(tight)} world(s) were made for a smaller robot than {robot.name} "
            f"(footprint radius {robot.footprint_radius_m} m): it may not fit through "
            f"{', '.join(tight[:5])}{' ...' if len(tight) > 5 else ''}",
            file=sys.stderr,
        )
    return [for_model(w, robot, folder) for w in worlds]


def command_line(args: argparse.Namespace) -> str:
    parts = ["pnav bench nav", f"--suite {args.suite}", f"--runs {args.runs}"]
    for option in ("model", "levels", "worlds", "combos", "json", "report", "compare"):
        if getattr(args, option, None) is not None:
            parts.append(f"--{option} {getattr(args, option)}")
    return " ".join(parts + (["--monolith"] if args.monolith else []))


def run(args: argparse.Namespace) -> int:
    """Run a parsed ``pnav bench nav``; 0, 1 when some run failed with an error, 130 when
    interrupted (after writing what was done)."""
    import uvloop

    from pnav.bench.figures import emit, machine
    from pnav.bench.nav import nav_report, run_diff
    from pnav.bench.nav.robots import resolve_model
    from pnav.bench.nav.stack_episode import MAX_LAG_S
    from pnav.bench.nav.worldfile import load_suite

    if args.runs < 1:
        raise UsageError("--runs must be 1 or more")
    combos = pick_combos(args.combos, shipped_combos(), shipped_combos(learned=True))
    # what the user typed is checked before the suite loads (seconds for a large one)
    robot = resolve_model(args.model) if getattr(args, "model", None) else None
    before: list[dict[str, Any]] = []
    if args.compare is not None:
        try:
            before = json.loads(args.compare.read_text())["runs"]
        except (OSError, ValueError, KeyError) as exc:
            raise UsageError(f"--compare {args.compare}: not a bench nav JSON ({exc})") from None
    worlds = select_worlds(load_suite(args.suite), args.levels, args.worlds)
    logs = args.report / "logs" if args.report else Path(tempfile.mkdtemp(prefix="pnav-nav-"))
    worlds = with_model(worlds, robot, logs / "worlds")
    monolith = load_monolith() if args.monolith else None
    plan = Plan(worlds, combos, args.runs, logs, args.report, monolith, pacing=args.pacing)
    plan.keep_db = getattr(args, "keep_db", None)
    total = len(worlds) * len(combos) * args.runs * (2 if monolith else 1)
    print(f"{total} episodes; logs in {logs}", file=sys.stderr)
    out = sys.stderr if args.json == "-" else sys.stdout  # keep stdout JSON-only then
    progress = Progress(total, out=out)
    date = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    records: list[RunRecord] = []
    interrupted = False
    from pnav.bench.nav.workers import EpisodeWorkers

    plan.workers = None if args.in_process else EpisodeWorkers()
    try:
        uvloop.run(execute(plan, progress, records))
    except KeyboardInterrupt:
        if not records:
            raise
        interrupted = True  # Ctrl-C: report the runs done so far, and say so
    finally:
        if plan.workers is not None:
            plan.workers.close()
        progress.close()
    meta = {
        "benchmark": "nav",
        "command": command_line(args),
        "date": date,
        "wall_s": round(time.monotonic() - progress.started, 1),
        "machine": machine(),
        "suite": str(args.suite),
        "model": getattr(args, "model", None) or "the world's own",
        "goal_tolerance_m": sorted({w.goal_tolerance_m for w in worlds}),
        "worlds": [w.name for w in worlds],
        "combos": [c.label for c in combos],
        "runs_per_world": args.runs,
        "pacing": args.pacing,
        "max_lag_s": MAX_LAG_S,
        "interrupted": interrupted,
    }
    for line in run_diff.summary_lines(records, before):
        print(line, file=out)
    emit(nav_report.document(records, meta), args.json)
    if args.report is not None:
        args.report.mkdir(parents=True, exist_ok=True)
        (args.report / "README.md").write_text(nav_report.readme(records, meta))
        print(f"wrote {args.report / 'README.md'}", file=out)
    if interrupted:
        return 130
    return 1 if any(r.end == "error" for r in records) else 0

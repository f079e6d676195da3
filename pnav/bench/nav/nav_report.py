"""What ``pnav bench nav`` prints and writes: the runs, their summaries, what running them
cost (the stack's, and the monolith's when asked), as text tables, JSON and a README.

Everything here works on finished ``RunRecord``s, so it is tested with made-up runs; the
runs themselves come from ``pnav.bench.nav.runner``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

from pnav.bench.figures import percentiles
from pnav.bench.nav.scores import RunResult, Summary, summarize, summarize_by

STACK, MONOLITH = "stack", "monolith"
# the JSON keeps a trajectory point per this much sim time: enough to redraw or compare a
# run, at a sixth of the 30 Hz odometry's size
TRAJECTORY_STEP_S = 0.2


@dataclass
class RunRecord:
    """One run of one combo in one world, one way (the stack or the monolith), scored."""

    world: str
    level: str
    combo: str  # Combo.label, e.g. GOTO_AVOID/turn_then_move
    run: int
    seed: int
    mode: str  # STACK or MONOLITH
    end: str  # the episode's own end: goal, collision, timeout, stalled; or error
    result: RunResult
    trajectory: list[tuple[float, float, float]] = field(default_factory=list)  # (t, x, y)
    collisions: list[tuple[float, float, float, str]] = field(default_factory=list)
    wall_s: float = 0.0  # the whole episode, the stack's start-up included
    run_wall_s: float = 0.0  # first decision to the end
    cpu_s: float = 0.0  # over the same span
    cpu_by_role: dict[str, float] = field(default_factory=dict)
    gate_timeouts: int | None = None  # the sim's pacing gave up waiting this often
    gate_waits_per_sim_s: float | None = None  # the sim waited for the stack this often
    latency_ms: list[float] = field(default_factory=list)  # the monolith's sense-to-act
    log_dir: str = ""
    error: str = ""
    png: str = ""  # file name in the report folder

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        out.update(self.result.to_json(), result=None, latency_ms=percentiles(self.latency_ms))
        out["trajectory"], last = [], -math.inf
        for i, (t, x, y) in enumerate(self.trajectory):
            if t - last >= TRAJECTORY_STEP_S or i == len(self.trajectory) - 1:
                out["trajectory"].append([round(t, 3), round(x, 3), round(y, 3)])
                last = t
        return {
            k: round(v, 4) if isinstance(v, float) else v for k, v in out.items() if k != "result"
        }


@dataclass(frozen=True)
class Table:
    title: str
    headers: list[str]
    rows: list[list[str]]


def table(title: str, headers: str, rows: list[list[str]]) -> Table:
    """``headers`` separated by "|" (some have spaces)."""
    return Table(title, headers.split("|"), rows)


def text(t: Table) -> str:
    """Aligned plain text, for the terminal."""
    widths = [max(len(c) for c in col) for col in zip(t.headers, *t.rows, strict=True)]
    rows = [
        "  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in [t.headers, *t.rows]
    ]
    return "\n".join([t.title, *rows])


def markdown(t: Table) -> str:
    lines = [f"**{t.title}**", "", "| " + " | ".join(t.headers) + " |"]
    lines.append("|" + "|".join("---" for _ in t.headers) + "|")
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in t.rows])


def _pct(x: float) -> str:
    return f"{100 * x:.0f} %"


def _num(x: float | None, digits: int = 1) -> str:
    return "-" if x is None else f"{x:.{digits}f}"


def of(records: Iterable[RunRecord], mode: str, combo: str | None = None) -> list[RunRecord]:
    return [r for r in records if r.mode == mode and combo in (None, r.combo)]


def _by_level(runs: Sequence[RunRecord]) -> dict[tuple[str, str], Summary]:
    """(level, combo) -> summary, in the runs' order: levels easy to hard, combos within."""
    grouped = summarize_by((f"{r.level} {r.combo}", r.result) for r in runs)
    return {(k.split(" ")[0], k.split(" ")[1]): s for k, s in grouped.items()}


def summaries(records: Sequence[RunRecord]) -> dict[str, Any]:
    """Per mode: per combo, and per combo and level (JSON-ready)."""
    out: dict[str, Any] = {}
    for mode in (STACK, MONOLITH):
        if runs := of(records, mode):
            nested: dict[str, dict[str, Any]] = {}
            for (level, combo), s in _by_level(runs).items():
                nested.setdefault(combo, {})[level] = s.to_json()
            by_combo = summarize_by((r.combo, r.result) for r in runs)
            out[mode] = {
                "by_combo": {c: s.to_json() for c, s in by_combo.items()},
                "by_combo_level": nested,
            }
    return out


SUMMARY = "runs|success|collision|timeout|stopped|time s|SPL|score"


def _summary_row(label: list[str], s: Summary) -> list[str]:
    rates = (s.success_rate, s.collision_rate, s.timeout_rate, s.stopped / s.runs)
    score = [f"{s.mean_spl:.3f}", f"{s.mean_score:.3f}"]
    return [*label, str(s.runs), *map(_pct, rates), _num(s.mean_success_time_s), *score]


def summary_tables(records: Sequence[RunRecord], mode: str = STACK) -> list[Table]:
    """Per combo, then per level and combo. "time s" is the mean sim time of the
    successes; SPL and score are means over all runs (a failure counts 0); "stopped" ended
    early without reaching the goal (the stack stalled, or the run failed with an error)."""
    if not (runs := of(records, mode)):
        return []
    by_combo = summarize_by((r.combo, r.result) for r in runs)
    return [
        table(
            f"{mode}: per combo",
            f"combo|{SUMMARY}",
            [_summary_row([c], s) for c, s in by_combo.items()],
        ),
        table(
            f"{mode}: per level and combo",
            f"level|combo|{SUMMARY}",
            [_summary_row([lv, c], s) for (lv, c), s in _by_level(runs).items()],
        ),
    ]


def cost(runs: Sequence[RunRecord]) -> dict[str, Any]:
    """Sim seconds driven; wall and CPU seconds per sim second over the runs that drove (an
    error has no sim time); the whole episode's mean wall time; gate timeouts."""
    driven = [r for r in runs if r.end != "error" and r.result.time_s > 0]
    sim = sum(r.result.time_s for r in driven)
    latency = [v for r in runs for v in r.latency_ms]
    gates = [r.gate_timeouts for r in runs if r.gate_timeouts is not None]
    return {
        "sim_s": round(sim, 3),
        "wall_per_sim_s": round(sum(r.run_wall_s for r in driven) / sim, 4) if sim else None,
        "cpu_per_sim_s": round(sum(r.cpu_s for r in driven) / sim, 4) if sim else None,
        "episode_wall_s_mean": round(sum(r.wall_s for r in runs) / len(runs), 3),
        "gate_timeouts": sum(gates) if gates else None,  # None: no gate (the monolith)
        "latency_ms": {k: round(v, 3) for k, v in percentiles(latency).items()},
        "cpu_ms_per_sim_s_by_role": _cpu_by_role(driven, sim),
        "gate_waits_per_sim_s": _waits_per_sim_s(driven, sim),
    }


def _cpu_by_role(driven: Sequence[RunRecord], sim: float) -> dict[str, float]:
    """Each process role's CPU (ms) per sim second over ``driven`` (sim seconds ``sim``),
    most first; {} where no run measured its processes (the monolith is one process)."""
    totals: dict[str, float] = {}
    for r in driven:
        for role, cpu_s in r.cpu_by_role.items():
            totals[role] = totals.get(role, 0.0) + cpu_s
    if not sim:
        return {}
    return {role: round(1000.0 * totals[role] / sim, 1) for role in _most_first(totals)}


def _most_first(totals: dict[str, float]) -> list[str]:
    """The roles of ``totals``, largest first (ties by name)."""
    return [role for role, _ in sorted(totals.items(), key=lambda kv: (-kv[1], kv[0]))]


def _waits_per_sim_s(driven: Sequence[RunRecord], sim: float) -> float | None:
    """The pacing's waits per sim second, weighted by each run's sim time (None: not read)."""
    rated = [(r.gate_waits_per_sim_s, r.result.time_s) for r in driven]
    known = [(rate, t) for rate, t in rated if rate is not None]
    if not known or not sim:
        return None
    return round(sum(rate * t for rate, t in known) / sum(t for _, t in known), 1)


def _ratio(a: float | None, b: float | None) -> float | None:
    return None if a is None or b is None or b <= 0 else round(a / b, 3)


RATIOS = ("cpu_per_sim_s", "wall_per_sim_s", "latency_p50")


def costs(records: Sequence[RunRecord]) -> dict[str, Any]:
    """Per combo: each mode's cost and, with both, the ratios stack / monolith (JSON-ready)."""
    out: dict[str, Any] = {}
    for combo in dict.fromkeys(r.combo for r in records):
        entry = {m: cost(runs) for m in (STACK, MONOLITH) if (runs := of(records, m, combo))}
        if len(entry) == 2:
            st, mo = entry[STACK], entry[MONOLITH]
            entry["ratio"] = {k: _ratio(st[k], mo[k]) for k in RATIOS[:2]}
            entry["ratio"]["latency_p50"] = _ratio(
                st["latency_ms"].get("p50"), mo["latency_ms"].get("p50")
            )
        out[combo] = entry
    return out


def _latency(c: dict[str, Any]) -> str:
    lat = c["latency_ms"]
    return f"{_num(lat.get('p50'), 2)} / {_num(lat.get('p99'), 2)}" if lat else "-"


def cost_table(records: Sequence[RunRecord]) -> Table:
    """Per combo and mode: wall and CPU seconds (every process of the stack) per sim second
    from the first decision to the end, sense-to-act latency, and the whole episode's wall
    time with start-up."""
    rows = []
    for combo, entry in costs(records).items():
        for mode in (m for m in (STACK, MONOLITH) if m in entry):
            c = entry[mode]
            figures = [_num(c["wall_per_sim_s"], 3), _num(c["cpu_per_sim_s"], 3), _latency(c)]
            rows.append([combo, mode, f"{c['sim_s']:.0f}", *figures])
            gate = "-" if c["gate_timeouts"] is None else str(c["gate_timeouts"])
            rows[-1] += [f"{c['episode_wall_s_mean']:.1f}", gate]
    headers = "combo|mode|sim s|wall s/sim s|CPU s/sim s|latency ms p50 / p99|episode wall s"
    return table("what the runs cost", headers + "|gate timeouts", rows)


def role_table(records: Sequence[RunRecord]) -> Table | None:
    """Per combo: where the stack's CPU goes, each process role's ms per sim second, next to
    the monolith's whole process and the sim's pacing waits per sim second (lockstep: one
    round of every participant's status each); None when no run measured its processes."""
    entries = costs(records)
    roles: dict[str, float] = {}
    for entry in entries.values():
        for role, ms in entry.get(STACK, {}).get("cpu_ms_per_sim_s_by_role", {}).items():
            roles[role] = roles.get(role, 0.0) + ms
    if not roles:
        return None
    order = _most_first(roles)
    rows = []
    for combo, entry in entries.items():
        st = entry.get(STACK)
        if st is None or not st["cpu_ms_per_sim_s_by_role"]:
            continue
        mine = st["cpu_ms_per_sim_s_by_role"]
        mono = entry.get(MONOLITH, {}).get("cpu_per_sim_s")
        figures = [*(mine.get(role) for role in order), sum(mine.values())]
        figures += [None if mono is None else mono * 1000.0, st["gate_waits_per_sim_s"]]
        rows.append([combo, *(_num(x, 1) for x in figures)])
    headers = "|".join(["combo", *order, "stack", "monolith", "pacing waits / sim s"])
    return table("where the stack's CPU goes, ms per sim second", headers, rows)


def comparison_table(records: Sequence[RunRecord]) -> Table | None:
    """Stack and monolith per combo, side by side, and the ratios stack / monolith; None
    unless both ran."""
    rows = []
    for combo, entry in ((c, e) for c, e in costs(records).items() if "ratio" in e):
        s, m = (summarize(r.result for r in of(records, x, combo)) for x in (STACK, MONOLITH))
        st, mo, ratio = entry[STACK], entry[MONOLITH], entry["ratio"]
        rows.append(
            [
                combo,
                f"{_pct(s.success_rate)} / {_pct(m.success_rate)}",
                f"{s.mean_spl:.3f} / {m.mean_spl:.3f}",
                f"{_num(s.mean_success_time_s)} / {_num(m.mean_success_time_s)}",
                *(f"{_num(ratio[k], 2)}" for k in RATIOS),
                f"{_latency(st)} vs {_latency(mo)}",
            ]
        )
    headers = "combo|success|SPL|time s|CPU x|wall x|latency x|latency ms p50 / p99"
    title = "stack / monolith (x: the stack's figure per sim second, or p50, over the monolith's)"
    return table(title, headers, rows) if rows else None


def attention(records: Sequence[RunRecord]) -> list[str]:
    """Runs whose figures need a look: errors, stalls, and runs whose pacing failed."""
    lines = []
    for r in records:
        name = f"{r.world} {r.combo} run {r.run} ({r.mode})"
        if r.end == "error":
            lines.append(f"{name}: error: {r.error}")
        elif r.end == "stalled":
            lines.append(f"{name}: stalled: the robot stopped getting anywhere (wall-time cap)")
        if r.gate_timeouts:
            lines.append(
                f"{name}: {r.gate_timeouts} gate timeout(s): the sim stopped waiting for the"
                " stack, so this run's sim time depended on the machine's load"
            )
    return lines


def run_table(records: Sequence[RunRecord], *, links: bool) -> Table:
    rows = []
    for r in records:
        res, picture = r.result, (f"[{r.png}]({r.png})" if links else r.png) if r.png else "-"
        rows.append([r.world, r.level, r.combo, str(r.run), r.mode, res.outcome, r.end])
        rows[-1] += [f"{res.time_s:.2f}", f"{res.path_length_m:.2f}", f"{res.spl:.3f}"]
        rows[-1] += [f"{res.score:.3f}", str(res.collision_count), picture]
    headers = "world|level|combo|run|mode|outcome|end|time s|path m|SPL|score|hits|picture"
    return table("every run", headers, rows)


def tables(records: Sequence[RunRecord]) -> list[Table]:
    extra = [t for t in (role_table(records), comparison_table(records)) if t is not None]
    out = [*summary_tables(records, STACK), *summary_tables(records, MONOLITH)]
    return [*out, cost_table(records), *extra]


LEGEND = """\
"time s" is the mean sim time of the successes; SPL and score are means over all runs, a
failure counting 0; "stopped" runs ended early away from the goal (the stack stalled, or the
run failed with an error). Cost: wall and CPU seconds per sim second from the run's first
decision to its end, CPU summed over every process of the stack (the services, Postgres, and
the launcher with its Zenoh router); "episode wall s" also counts the stack's start-up and
shut-down. A gate timeout means the sim stopped waiting for the stack: that run's sim time
then depended on the machine's load."""


def readme(records: Sequence[RunRecord], meta: dict[str, Any]) -> str:
    """The report folder's README.md: how it was made, the summaries, then every run."""
    m = meta["machine"]
    parts = [
        "# Navigation benchmark (`pnav bench nav`)",
        "",
        f"```sh\n{meta['command']}\n```",
        "",
        f"- {meta['date']}, {meta['wall_s'] / 60:.1f} min wall",
        f"- {m.get('cpus')} cores, {m.get('memory_gib')} GiB, {m.get('platform')},"
        f" Python {m.get('python')}",
        f"- suite `{meta['suite']}`, {len(meta['worlds'])} worlds; combos "
        + ", ".join(f"`{c}`" for c in meta["combos"])
        + f"; {meta['runs_per_world']} run(s) each, seed = run",
        "- the sim at `--rate max`, "
        + (
            f"paced by the stack (`--max-lag {meta['max_lag_s']}`)"
            if meta.get("pacing") == "lag"
            else "in lockstep with the stack (the same world and seed give the same run)"
        )
        + "; success: within the goal tolerance"
        + f" ({' / '.join(f'{t:g}' for t in meta.get('goal_tolerance_m', [0.3]))} m),"
        + " no collision, within the time limit"
        + (f"; robot model `{meta['model']}`" if meta.get("model") else ""),
        "",
        *(["- **interrupted** (Ctrl-C): only the runs done so far"] if meta["interrupted"] else []),
        "## Summary",
        "",
    ]
    for t in tables(records):
        parts += [markdown(t), ""]
    parts += [LEGEND, ""]
    parts += ["## Runs that need a look", ""]
    notes = [f"- {line}" for line in attention(records)]
    parts += notes or ["None: no errors, stalls or gate timeouts."]
    return "\n".join([*parts, "", "## Runs", "", markdown(run_table(records, links=True)), ""])


def document(records: Sequence[RunRecord], meta: dict[str, Any]) -> dict[str, Any]:
    """The JSON: how the runs were made, the summaries and costs, then every run."""
    runs = [r.to_json() for r in records]
    return {**meta, "summary": summaries(records), "cost": costs(records), "runs": runs}

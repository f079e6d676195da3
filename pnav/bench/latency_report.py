"""Figures and the printed table of ``pnav bench latency`` (the runs are in latency.py)."""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import uvloop

from pnav.bench import provenance_samples as prov
from pnav.bench.figures import emit, machine, percentiles
from pnav.bench.sense_to_act import LINKS, measure

# the targets: robots -> p99 ms, on a 2-core machine
TARGETS_MS = {1: 5.0, 10: 10.0, 50: 50.0}
LIMITS_MS = (5.0, 50.0)
LAYOUTS = ("auto", "composed", "separate")
# the stack's p99 within this many times the floor measured in the same run (the chain)
FLOOR_RATIO_TARGET = 2.0


def _choices(text: str, allowed: Sequence[str], option: str, what: str) -> tuple[str, ...]:
    """A comma-separated list of ``allowed`` names, in the order given, each once; a list
    that is empty or names another is refused, naming ``option``."""
    names = tuple(dict.fromkeys(part.strip() for part in text.split(",") if part.strip()))
    if not names or any(name not in allowed for name in names):
        raise SystemExit(
            f"pnav bench latency: {option} {text!r}: each {what} must be one of "
            f"{', '.join(allowed)}"
        )
    return names


def parse_links(text: str) -> tuple[str, ...]:
    """``--robot-link``: ``native``, ``ros2`` or both, comma-separated, in the order given."""
    return _choices(text, LINKS, "--robot-link", "link")


def parse_layouts(text: str | None) -> tuple[str | None, ...]:
    """``--processes``: ``auto``, ``composed``, ``separate`` or several, comma-separated, one
    run each per size (None: one run, the layout PNAV_PROCESSES or ``auto`` gives)."""
    return (None,) if text is None else _choices(text, LAYOUTS, "--processes", "layout")


def target_for(robots: int) -> float | None:
    """The p99 target of the nearest listed fleet size at or above ``robots``."""
    for n in sorted(TARGETS_MS):
        if robots <= n:
            return TARGETS_MS[n]
    return None


def latency_figures(samples: Sequence[prov.Sample]) -> dict[str, Any]:
    totals = [s.total_ms for s in samples]
    out: dict[str, Any] = {k: round(v, 3) for k, v in percentiles(totals).items()}
    for limit in LIMITS_MS:
        out[f"share_over_{limit:g}ms"] = round(prov.share_over(totals, limit), 4)
    return out


def summarise(run: dict[str, Any]) -> dict[str, Any]:
    """A run from latency.measure with its samples turned into figures (JSON-ready)."""
    samples: list[prov.Sample] = run.pop("samples_raw")
    stages = {
        name: {
            k: round(v, 3) for k, v in percentiles([s.stages_ms()[name] for s in samples]).items()
        }
        for name in prov.STAGES
    }
    by_source = {
        source: {"samples": len(group), **latency_figures(group)}
        for source in sorted({s.source for s in samples})
        for group in [[s for s in samples if s.source == source]]
    }
    target = target_for(run["robots"])
    figures = latency_figures(samples)
    met = None if target is None or not samples else figures["p99"] < target
    return {
        **run,
        "latency_ms": figures,
        "stages_ms": stages,
        "by_source": by_source,
        "target_p99_ms": target,
        "target_met": met,
    }


def _label(run: dict[str, Any]) -> str:
    link = "" if run.get("link", "native") == "native" else f", {run['link']} link"
    layout = f"{run['layout']:>8} " if "layout" in run else ""
    return f"  {layout}{run['robots']:>3} robots{link}: "


def _cpu(run: dict[str, Any]) -> float:
    return float(sum(p["cpu_percent"] for p in run["processes"].values()))


def _pss(run: dict[str, Any]) -> float:
    return float(sum(p["peak_pss_mb"] for p in run["processes"].values()))


def separation_price(results: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per size and link measured both ways: what one process per service costs over the
    composed layout (separate minus composed), p50/p99 ms, CPU % of a core and PSS MB."""
    by_key = {(r["robots"], r.get("link", "native"), r.get("layout")): r for r in results}
    prices = []
    for (robots, link, layout), separate in by_key.items():
        composed = by_key.get((robots, link, "composed"))
        if layout != "separate" or composed is None:
            continue
        price: dict[str, Any] = {"robots": robots, "link": link}
        for q in ("p50", "p99"):
            a, b = separate["latency_ms"].get(q), composed["latency_ms"].get(q)
            price[f"{q}_ms"] = None if a is None or b is None else round(a - b, 3)
        price["cpu_percent"] = round(_cpu(separate) - _cpu(composed), 1)
        price["pss_mb"] = round(_pss(separate) - _pss(composed), 1)
        price["processes"] = len(separate["processes"]) - len(composed["processes"])
        prices.append(price)
    return prices


def floor(robots: int, seconds: float) -> dict[str, Any]:
    """The design's floor at ``robots`` (``python -m pnav.bench.chain``, its own processes,
    run after the stack's run, not beside it): its figures, or ``{"error": ...}``."""
    with tempfile.TemporaryDirectory(prefix="pnav-floor-") as tmp:
        out = Path(tmp) / "chain.json"
        argv = [sys.executable, "-m", "pnav.bench.chain", "--robots", str(robots)]
        argv += ["--seconds", f"{seconds:g}", "--json", str(out)]
        done = subprocess.run(argv, capture_output=True, text=True, timeout=seconds * 4 + 120)
        if done.returncode != 0 or not out.exists():
            return {"error": (done.stderr.strip().splitlines() or ["no figures"])[-1][:300]}
        (run,) = json.loads(out.read_text())["runs"]
    return {k: run[k] for k in ("samples", "sent", "p50_ms", "p95_ms", "p99_ms", "cpu_pct")}


def beside_floor(result: dict[str, Any], measured: dict[str, Any]) -> dict[str, Any]:
    """``result`` with the floor, the stack's p99 over the floor's, and whether it is within
    FLOOR_RATIO_TARGET (None: either p99 missing)."""
    p99 = result["latency_ms"].get("p99")
    base = measured.get("p99_ms")
    ratio = round(p99 / base, 2) if p99 is not None and base and base == base else None
    met = None if ratio is None else ratio <= FLOOR_RATIO_TARGET
    return {**result, "floor": measured, "p99_over_floor": ratio, "floor_target_met": met}


def table(results: Sequence[dict[str, Any]]) -> list[str]:
    head = (
        f"{'link':>6} {'layout':>8} {'robots':>6} {'repl':>4} {'samples':>7}"
        f" {'p50':>7} {'p95':>7} {'p99':>7} {'max':>7}"
        f" {'>5ms':>6} {'>50ms':>6} {'target':>7} {'rows/s':>7} {'sim x':>6} {'CPU %':>6}"
    )
    lines = ["sense-to-act latency, ms (sensor published by the sim -> command at the sim)", head]
    for r in results:
        lat = r["latency_ms"]
        rows = sum(r["rows_per_s"].values())
        cpu = _cpu(r)
        repl = max(r["replicas"].values(), default=1)
        layout = r.get("layout", "?")
        lead = f"{r.get('link', 'native'):>6} {layout:>8} {r['robots']:>6} {repl:>4}"
        target = "-" if r["target_p99_ms"] is None else f"<{r['target_p99_ms']:g}"
        mark = {True: " ok", False: " MISS", None: ""}[r["target_met"]]
        if "p50" not in lat:  # no sample: only the shares over the limits, of nothing
            lines.append(f"{lead} {0:>7}   no samples (see unmatched)")
            continue
        lines.append(
            f"{lead} {r['samples']:>7}"
            f" {lat['p50']:>7.2f} {lat['p95']:>7.2f} {lat['p99']:>7.2f} {lat['max']:>7.1f}"
            f" {lat['share_over_5ms']:>6.1%}"
            f" {lat['share_over_50ms']:>6.1%} {target:>7} {rows:>7.0f} {r['sim_rate']:>6.2f}"
            f" {cpu:>6.0f}{mark}"
        )
    lines.append("")
    lines.append(
        f"the design's floor (python -m pnav.bench.chain at 20 Hz, same robots, right after; "
        f"target: stack p99 <= {FLOOR_RATIO_TARGET:g}x floor)"
    )
    for r in results:
        f = r.get("floor")
        if f is None:
            continue
        if "error" in f:
            lines.append(_label(r) + f"floor not measured: {f['error']}")
            continue
        ratio = r["p99_over_floor"]
        mark = {True: " ok", False: " MISS", None: ""}[r["floor_target_met"]]
        lines.append(
            _label(r) + f"floor p50/p99 {f['p50_ms']:.2f}/{f['p99_ms']:.2f} ms "
            f"(CPU {f['cpu_pct']:.0f}%), stack p99 {r['latency_ms'].get('p99', float('nan')):.2f}"
            f" ms = {'-' if ratio is None else f'{ratio:.2f}'}x the floor{mark}"
        )
    prices = separation_price(results)
    if prices:
        lines.append("")
        lines.append(
            "the price of separate processes (separate minus composed, same size and link)"
        )
        for p in prices:
            p50, p99 = p["p50_ms"], p["p99_ms"]
            link = "" if p["link"] == "native" else f", {p['link']} link"
            lines.append(
                f"  {p['robots']:>3} robots{link}: p50 {'-' if p50 is None else f'{p50:+.2f}'} ms,"
                f" p99 {'-' if p99 is None else f'{p99:+.2f}'} ms, CPU {p['cpu_percent']:+.0f} %"
                f" of a core, PSS {p['pss_mb']:+.0f} MB, {p['processes']:+d} processes"
            )
    lines.append("")
    lines.append("per stage, p50 / p99 ms")
    for r in results:
        parts = [
            f"{name.replace('_to_', '->')} {st['p50']:.2f}/{st['p99']:.2f}"
            for name, st in r["stages_ms"].items()
            if st
        ]
        lines.append(_label(r) + ", ".join(parts))
    lines.append("")
    lines.append("per process: CPU % of one core, peak PSS MB")
    for r in results:
        procs = r["processes"]
        parts = [
            f"{name} {p['cpu_percent']:.0f}%/{p['peak_pss_mb']:.0f}" for name, p in procs.items()
        ]
        lines.append(_label(r) + ", ".join(parts))
    lines.append("")
    lines.append("change notifications lost, whole run (each process's own count: a seq skipped)")
    for r in results:
        parts = [f"{name} {n}" for name, n in r.get("notifications_lost", {}).items()]
        lines.append(_label(r) + (", ".join(parts) or "no count found"))
    lines.append("")
    lines.append("rules: mean / max ms per run of the rule, its queries included (engine_stats)")
    for r in results:
        parts = [
            f"{x['service']}.{x['rule']} {x['mean_ms']:.2f}/{x['max_ms']:.1f} (x{x['executed']})"
            for x in r.get("rules", [])
        ]
        lines.append(_label(r) + ", ".join(parts))
    return lines


def run(
    robots: Sequence[int],
    hz: float = 20.0,
    seconds: float = 30.0,
    replicas: dict[str, int] | None = None,
    json_path: str | None = None,
    links: Sequence[str] = ("native",),
    with_floor: bool = True,
    layouts: Sequence[str | None] = (None,),
) -> int:
    results = []
    for n in robots:
        runs = []
        for link in links:
            for layout in layouts:
                print(
                    f"running {n} robot(s) at {hz:g} Hz for {seconds:g} sim s, {link} link, "
                    f"processes {layout or 'as PNAV_PROCESSES or auto'} ...",
                    flush=True,
                )
                measured_run = measure(n, hz, seconds, replicas or {}, link, layout)
                runs.append(summarise(uvloop.run(measured_run)))
        if with_floor:  # one floor per size: it has no robot link
            print(f"the floor at {n} robot(s) for {seconds:g} s ...", flush=True)
            measured = floor(n, seconds)
            runs = [beside_floor(result, measured) for result in runs]
        results.extend(runs)
    for line in table(results):
        print(line)
    report = {"benchmark": "latency", "machine": machine(), "runs": results}
    emit({**report, "separation_price": separation_price(results)}, json_path)
    return 0

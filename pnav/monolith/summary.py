"""Figures of an outcome, the same way for the monolith and the stack, for people and JSON."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pnav.bench.nav.scores import path_length
from pnav.bench.nav.stack_episode import Outcome
from pnav.monolith.monolith_episode import MonolithOutcome


def percentile(values: list[float], q: float) -> float | None:
    return float(np.percentile(values, q)) if values else None


def summary(outcome: Outcome) -> dict[str, Any]:
    """end, sim time, path length, cost; with the monolith's latency and sources."""
    sim_s = outcome.time_s
    out: dict[str, Any] = {
        "end": outcome.end,
        "time_s": round(sim_s, 3),
        "path_m": round(path_length([(x, y) for _t, x, y in outcome.trajectory]), 3),
        "final_distance_m": _round(outcome.final_distance_m),
        "collisions": len(outcome.collisions),
        "wall_s": round(outcome.wall_s, 3),
        "run_wall_s": round(outcome.run_wall_s, 3),
        "cpu_s": round(outcome.cpu_s, 3),
        # both per sim second of the run proper (first decision to the end)
        "cpu_per_sim_s": round(outcome.cpu_s / sim_s, 4) if sim_s > 0 else None,
        "real_time_factor": round(sim_s / outcome.run_wall_s, 1) if outcome.run_wall_s else None,
    }
    if isinstance(outcome, MonolithOutcome):
        lat = outcome.latency_ms
        out["latency_ms"] = {
            "samples": len(lat),
            "p50": _round(percentile(lat, 50)),
            "p99": _round(percentile(lat, 99)),
            "max": _round(max(lat) if lat else None),
        }
        out["watchdog_stops"] = outcome.watchdog_stops
        out["rule_errors"] = outcome.rule_errors
        out["decided_by"] = outcome.decided_by
    return out


def _round(value: float | None, digits: int = 3) -> float | None:
    if value is None or not math.isfinite(value):
        return None
    return round(value, digits)


def describe(s: dict[str, Any]) -> str:
    """A few lines for a terminal."""
    lines = [
        f"end {s['end']} after {s['time_s']:.2f} s sim, path {s['path_m']:.2f} m, "
        f"final distance {s['final_distance_m']} m, collisions {s['collisions']}",
        f"wall {s['wall_s']:.2f} s (run {s['run_wall_s']:.2f} s, x{s['real_time_factor']} real "
        f"time), CPU {s['cpu_s']:.2f} s = {s['cpu_per_sim_s']} CPU s per sim s",
    ]
    lat = s.get("latency_ms")
    if lat is not None:
        lines.append(
            f"sense-to-act latency p50 {lat['p50']} ms, p99 {lat['p99']} ms, max {lat['max']} ms "
            f"({lat['samples']} samples)"
        )
    if "decided_by" in s:
        lines.append(
            "commands by source: "
            + ", ".join(f"{k or '(stop)'} {v}" for k, v in s["decided_by"].items())
            + f"; watchdog stops {s['watchdog_stops']}, rule errors {s['rule_errors']}"
        )
    return "\n".join(lines)

"""The faults benchmark's table and JSON, and its verdict against the targets."""

from __future__ import annotations

from dataclasses import asdict
from typing import Any

from pnav.bench.faults.trial import Result

MAX_AFTER_COMMAND_M = 0.15


def misses(r: Result) -> list[str]:
    """The targets ``r`` missed (empty: all met)."""
    out = []
    if not r.safe:
        out.append("outcome")
    if r.collisions or r.contacts:
        out.append("collisions")
    if r.max_after_command_m is not None and r.max_after_command_m > MAX_AFTER_COMMAND_M:
        out.append("driven after the last command")
    if r.rows_lost:
        out.append("rows lost")
    if r.forged_believed:
        out.append("forged messages believed")
    if r.breaches:
        out.append("breached")
    return out


def _fmt(value: float | None, spec: str = ".2f") -> str:
    return "-" if value is None else format(value, spec)


def table(results: list[Result]) -> str:
    head = (
        f"{'fault':<20} {'coll':>4} {'cont':>4} {'after_m':>7} {'lost':>4} {'restart':>7} "
        f"{'back_s':>6} {'wall_s':>6}  {'ok':<3} outcome"
    )
    lines = [head, "-" * len(head)]
    for r in results:
        lost = sum(r.rows_lost.values())
        ok = "yes" if not misses(r) else "NO"
        lines.append(
            f"{r.fault:<20} {r.collisions:>4} {_fmt(r.contacts, 'd'):>4} "
            f"{_fmt(r.max_after_command_m, '.3f'):>7} {lost:>4} {_fmt(r.restart_s):>7} "
            f"{_fmt(r.recovered_s):>6} {r.wall_s:>6.1f}  {ok:<3} {r.outcome[:90]}"
        )
        for note in r.notes:
            lines.append(f"{'':<20}   note: {note[:100]}")
        if r.rows_lost:
            lines.append(f"{'':<20}   rows lost: {r.rows_lost}")
        for breach in r.breaches:
            lines.append(f"{'':<20}   BREACH: {breach[:100]}")
    failed = [r.fault for r in results if misses(r)]
    lines.append(
        f"{len(results) - len(failed)}/{len(results)} faults met every target"
        + (f"; missed: {', '.join(failed)}" if failed else "")
    )
    return "\n".join(lines)


def as_json(results: list[Result], meta: dict[str, Any]) -> dict[str, Any]:
    return {
        **meta,
        "targets": {
            "outcome": "reached, or failed/refused with a reason",
            "collisions": 0,
            "max_after_command_m": MAX_AFTER_COMMAND_M,
            "rows_lost": 0,
            "forged_believed": 0,
            "breaches": 0,
        },
        "faults": [{**asdict(r), "misses": misses(r)} for r in results],
    }

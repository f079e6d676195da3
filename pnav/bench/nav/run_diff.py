"""``--compare``: the same runs (world, combo, k) of two ``pnav bench nav`` JSON files side by
side: outcome, time, and how far the driven paths parted."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from pnav.bench.nav.nav_report import RunRecord, attention, tables, text


def _to_polyline(p: npt.NDArray[np.float64], q: npt.NDArray[np.float64]) -> float:
    """The largest distance from a point of ``p`` to the polyline through ``q`` (n, 2)."""
    if len(q) == 1:
        return float(np.sqrt(((p - q[0]) ** 2).sum(-1)).max())
    a, ab = q[:-1], np.diff(q, axis=0)
    rel = p[:, None, :] - a[None, :, :]
    t = np.clip((rel * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0.0, 1.0)
    gap = rel - t[..., None] * ab
    return float(np.sqrt((gap * gap).sum(-1)).min(axis=1).max())


def parted_m(a: Sequence[Sequence[float]], b: Sequence[Sequence[float]]) -> float:
    """How far two drives ([t, x, y] points) parted: the largest distance from a point of
    either to the other's polyline, so that the JSON's sparser points compare fairly with
    full odometry (NaN if one is empty)."""
    if not a or not b:
        return math.nan
    pa, pb = np.asarray(a, dtype=float)[:, -2:], np.asarray(b, dtype=float)[:, -2:]
    return max(_to_polyline(pa, pb), _to_polyline(pb, pa))


def compare(records: Sequence[RunRecord], before: Sequence[dict[str, Any]]) -> list[str]:
    """This run's records against an earlier JSON's runs, matched by world, combo, run and
    mode: outcome, time, and how far the paths parted (or that they are the same path, point
    for point, as a lockstep run repeats); one line each, then a count. Each record is
    compared in its JSON form, rounded as the earlier one was."""
    earlier = {(b["world"], b["combo"], b["run"], b["mode"]): b for b in before}
    lines, same, identical, matched, worst = [], 0, 0, 0, 0.0
    for r in records:
        if (b := earlier.get((r.world, r.combo, r.run, r.mode))) is None:
            continue
        now = r.to_json()
        dt = float(now["time_s"]) - float(b["time_s"])
        equal = now["outcome"] == b["outcome"]
        same_path = bool(now["trajectory"]) and now["trajectory"] == b.get("trajectory")
        matched, same, worst = matched + 1, same + equal, max(worst, abs(dt))
        identical += same_path
        path = (
            "the same path, point for point"
            if same_path
            else f"paths at most {parted_m(now['trajectory'], b.get('trajectory', [])):.3f} m apart"
        )
        lines.append(
            f"{r.world} {r.combo} run {r.run} ({r.mode}): {b['outcome']} -> {now['outcome']}"
            f"{'' if equal else ' DIFFERENT'}; time {float(b['time_s']):.3f} -> "
            f"{float(now['time_s']):.3f} s ({dt:+.3f}); {path}"
        )
    lines.append(
        f"{same} of {matched} runs with the same outcome, {identical} on the same path; "
        f"largest time change {worst:.3f} s"
    )
    return lines


def summary_lines(records: Sequence[RunRecord], before: Sequence[dict[str, Any]] = ()) -> list[str]:
    """What the terminal shows at the end: the tables, the runs needing a look, and the
    comparison with an earlier JSON if one was given."""
    lines = [line for t in tables(records) for line in (text(t), "")]
    lines += attention(records)
    return lines + (["", "against the earlier runs:", *compare(records, before)] if before else [])

"""A decision's provenance: the decision row, the recommendations it weighed, and the rows
each recommendation says it was derived from (its ``inputs``: ``{"laser_scan": 812,
"scan_stamp": 40.2, ...}``), back to the sensor rows the bridge wrote.

Sensor rows are pruned by the retention policy (CONTRACT.md, ``retention_policy``): an old
decision may name a scan that is gone, and says so rather than failing.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from datetime import datetime
from typing import Any

import services.dashboard.scene as scene
from services.dashboard.requests import Refused
from services.dashboard.store import DECISION_TABLES, PROVENANCE_TABLES, DashboardSource

Row = Mapping[str, Any]

PRUNED = "no longer in the table: the retention policy keeps each robot's newest rows only"


def plain(row: Row) -> dict[str, Any]:
    """A row as JSON: times as ISO 8601, non-finite numbers as null, a scan's ranges as a
    summary (360 numbers explain less than the nearest one)."""
    out: dict[str, Any] = {}
    for key, value in row.items():
        if isinstance(value, datetime):
            out[key] = value.isoformat()
        elif isinstance(value, bytes | bytearray | memoryview):
            out[key] = f"{len(bytes(value))} bytes"
        elif key == "ranges" and isinstance(value, list):
            hits = [r for r in value if r is not None and math.isfinite(r)]
            out["beams"] = len(value)
            out["hits"] = len(hits)
            out["nearest_m"] = round(min(hits), 3) if hits else None
        else:
            out[key] = scene.jsonable(value)
    return out


async def provenance(source: DashboardSource, table: str, row_id: int) -> dict[str, Any]:
    """404 for a table that holds no decisions or an id that is not there."""
    if table not in DECISION_TABLES:
        raise Refused(404, f"{table!r} holds no decisions; ask {' or '.join(DECISION_TABLES)}")
    row = await source.row(table, row_id)
    if row is None:
        raise Refused(404, f"no {table} row {row_id}")
    considered = [int(i) for i in row["considered_ids"] or ()]
    recs = sorted(
        await source.recommendations(considered) if considered else [],
        key=lambda r: (-int(r["priority"]), -int(r["id"])),
    )
    weighed = []
    for rec in recs:
        inputs = rec["inputs"] or {}
        rows = []
        for name, value in inputs.items():
            if name in PROVENANCE_TABLES and isinstance(value, int) and not isinstance(value, bool):
                found = await source.row(name, value)
                rows.append(
                    {
                        "table": name,
                        "id": value,
                        "row": None if found is None else plain(found),
                        "note": PRUNED if found is None else None,
                    }
                )
        weighed.append({**plain(rec), "won": rec["id"] == row["recommendation_id"], "rows": rows})
    missing = sorted(set(considered) - {int(r["id"]) for r in recs})
    return {
        "table": table,
        "decision": plain(row),
        "recommendations": weighed,
        "missing_recommendations": missing,
    }

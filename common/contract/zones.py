"""Keepout and speed zones: the zone table's rows (migration 14), their bounds and geometry.

A zone is a polygon in the map frame, closed implicitly, of kind ``keepout`` (the planner
never routes through it) or ``speed_limit`` (the bridge's safety layer caps the linear speed
of a robot whose centre is inside it). People write the rows (the CLI, dashboards: the SQL
here is theirs, with its notification); the planner and the bridge read them
(:func:`read_zones`). schema.sql is the authority on what a row may hold;
:func:`polygon_problem` and :func:`check_zone` say the same in Python so a tool can refuse
first, in words naming the field (tests/contract/test_zones.py holds the two together).
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Final

from common.contract import keys
from common.db import Database
from common.errors import ContractError

KEEPOUT: Final = "keepout"
SPEED_LIMIT: Final = "speed_limit"
KINDS: Final = (KEEPOUT, SPEED_LIMIT)

MIN_VERTICES: Final = 3
MAX_VERTICES: Final = 100
MAX_ABS_M: Final = 1.0e5  # as goals: nothing beyond it is ever reached
MIN_AREA_M2: Final = 0.01
MAX_SPEED_MPS: Final = 10.0  # as command velocities
MAX_DESCRIPTION_CHARS: Final = 1000
MAX_ZONES: Final = 256  # rows in the table (a trigger: constraint zone_count)
NAME: Final = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")
_ROBOT_ID = re.compile(r"^[A-Za-z0-9_-]+$")

READ_SQL = "SELECT name, kind, xs, ys, max_speed_mps, robot_id, description FROM zone ORDER BY name"
INSERT_SQL = (
    "INSERT INTO zone (name, kind, xs, ys, max_speed_mps, robot_id, description) "
    "VALUES ($1, $2, $3, $4, $5, $6, $7) RETURNING name"
)
DELETE_SQL = "DELETE FROM zone WHERE name = $1 RETURNING name"


@dataclass(frozen=True)
class Zone:
    """One zone row."""

    name: str
    kind: str
    xs: tuple[float, ...]
    ys: tuple[float, ...]
    max_speed_mps: float | None = None
    robot_id: str | None = None  # None: every robot
    description: str = ""

    @property
    def keepout(self) -> bool:
        return self.kind == KEEPOUT

    @cached_property
    def box(self) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1): the polygon's bounding box, worked out once."""
        return min(self.xs), min(self.ys), max(self.xs), max(self.ys)

    def applies_to(self, robot_id: str) -> bool:
        return self.robot_id is None or self.robot_id == robot_id

    def contains(self, x: float, y: float) -> bool:
        """Whether (x, y) lies inside the polygon (even-odd rule; the boundary counts as
        inside when a ray along it meets it, as a point on a left or bottom edge does)."""
        x0, y0, x1, y1 = self.box
        if not (x0 <= x <= x1 and y0 <= y <= y1):
            return False  # the cheap test first: most zones are far from most points
        inside = False
        xs, ys = self.xs, self.ys
        j = len(xs) - 1
        for i in range(len(xs)):
            xi, yi, xj, yj = xs[i], ys[i], xs[j], ys[j]
            if (yi > y) != (yj > y) and x < (xj - xi) * (y - yi) / (yj - yi) + xi:
                inside = not inside
            j = i
        return inside

    def image(self) -> dict[str, Any]:
        """The row as JSON (the dashboard's API)."""
        return {
            "name": self.name,
            "kind": self.kind,
            "xs": list(self.xs),
            "ys": list(self.ys),
            "max_speed_mps": self.max_speed_mps,
            "robot_id": self.robot_id,
            "description": self.description,
        }

    @classmethod
    def of_row(cls, row: Any) -> Zone:
        return cls(
            row["name"],
            row["kind"],
            tuple(float(v) for v in row["xs"]),
            tuple(float(v) for v in row["ys"]),
            None if row["max_speed_mps"] is None else float(row["max_speed_mps"]),
            row["robot_id"],
            row["description"] or "",
        )


def _cross(ox: float, oy: float, ax: float, ay: float, bx: float, by: float) -> float:
    """(a - o) x (b - o)."""
    return (ax - ox) * (by - oy) - (ay - oy) * (bx - ox)


def _on(ax: float, ay: float, bx: float, by: float, px: float, py: float) -> bool:
    """Whether p, collinear with segment a-b, lies within its bounding box."""
    return min(ax, bx) <= px <= max(ax, bx) and min(ay, by) <= py <= max(ay, by)


def polygon_problem(xs: Sequence[float], ys: Sequence[float]) -> str | None:
    """What the zone table would refuse in the polygon (xs, ys), in the same words as
    schema.sql's zone_polygon_problem; None for a simple polygon within bounds."""
    n = len(xs)
    if n != len(ys):
        return f"polygon xs has {n} values but ys has {len(ys)}: one x and one y per vertex"
    if n < MIN_VERTICES:
        return (
            f"polygon has {n} vertices: at least 3 are needed (fewer make an open line, "
            "not an area)"
        )
    if n > MAX_VERTICES:
        return f"polygon has {n} vertices: at most {MAX_VERTICES}"
    for i, (x, y) in enumerate(zip(xs, ys, strict=True), start=1):
        if not (math.isfinite(x) and math.isfinite(y) and abs(x) <= MAX_ABS_M >= abs(y)):
            return (
                f"polygon vertex {i} (xs[{i}], ys[{i}]) must be finite and within "
                f"+-100000 m, got ({x}, {y})"
            )
    area = 0.0
    for i in range(n):
        j = (i + 1) % n
        if xs[i] == xs[j] and ys[i] == ys[j]:
            if j == 0:
                return (
                    f"polygon repeats vertex 1 at the end (vertex {n}): a zone is closed "
                    "implicitly, give each vertex once"
                )
            return f"polygon vertices {i + 1} and {j + 1} are the same point: a degenerate edge"
        area += xs[i] * ys[j] - xs[j] * ys[i]
    if all(_cross(xs[0], ys[0], xs[1], ys[1], xs[i], ys[i]) == 0 for i in range(2, n)):
        return "polygon is degenerate: its vertices are on one line"
    crossing = _crossing(xs, ys)
    if crossing is not None:
        return crossing
    if abs(area) / 2 < MIN_AREA_M2:
        return (
            f"polygon is degenerate: its area is {round(abs(area) / 2, 6)} m^2, at least "
            f"{MIN_AREA_M2} is needed"
        )
    return None


def _crossing(xs: Sequence[float], ys: Sequence[float]) -> str | None:
    n = len(xs)
    for i in range(n):
        ax, ay, bx, by = xs[i], ys[i], xs[(i + 1) % n], ys[(i + 1) % n]
        for j in range(i + 1, n):
            cx, cy, dx, dy = xs[j], ys[j], xs[(j + 1) % n], ys[(j + 1) % n]
            edges = f"polygon edges {i + 1} and {j + 1}"
            if j == i + 1 or (i == 0 and j == n - 1):
                if j == i + 1:
                    turn = (bx - ax) * (dy - cy) - (by - ay) * (dx - cx)
                    dot = (bx - ax) * (dx - cx) + (by - ay) * (dy - cy)
                else:
                    turn = (ax - cx) * (by - ay) - (ay - cy) * (bx - ax)
                    dot = (ax - cx) * (bx - ax) + (ay - cy) * (by - ay)
                if turn == 0 and dot < 0:
                    return f"{edges} fold back onto each other: a zone must not intersect itself"
                continue
            d1 = _cross(cx, cy, dx, dy, ax, ay)
            d2 = _cross(cx, cy, dx, dy, bx, by)
            d3 = _cross(ax, ay, bx, by, cx, cy)
            d4 = _cross(ax, ay, bx, by, dx, dy)
            if d1 * d2 < 0 and d3 * d4 < 0:
                return (
                    f"{edges} cross: a zone must not intersect itself (give the vertices in "
                    "order around it)"
                )
            if (
                (d1 == 0 and _on(cx, cy, dx, dy, ax, ay))
                or (d2 == 0 and _on(cx, cy, dx, dy, bx, by))
                or (d3 == 0 and _on(ax, ay, bx, by, cx, cy))
                or (d4 == 0 and _on(ax, ay, bx, by, dx, dy))
            ):
                return f"{edges} touch: a zone must not intersect itself"
    return None


def check_zone(zone: Zone) -> None:
    """ContractError naming the first field the zone table would refuse, if any."""
    if not NAME.match(zone.name):
        raise ContractError(
            f"zone name must be 1 to 64 letters, digits, '_', '.' or '-', got {zone.name!r}"
        )
    if zone.kind not in KINDS:
        raise ContractError(f"zone kind must be keepout or speed_limit, got {zone.kind!r}")
    speed = zone.max_speed_mps
    if zone.kind == SPEED_LIMIT:
        if speed is None or not (math.isfinite(speed) and 0 < speed <= MAX_SPEED_MPS):
            raise ContractError(
                "zone max_speed_mps of a speed_limit zone must be a finite speed in "
                f"(0, {MAX_SPEED_MPS:g}] m/s, got {speed!r}"
            )
    elif speed is not None:
        raise ContractError(f"zone max_speed_mps must be empty for a keepout zone, got {speed!r}")
    if zone.robot_id is not None and not _ROBOT_ID.match(zone.robot_id):
        raise ContractError(f"zone robot_id must match [A-Za-z0-9_-]+, got {zone.robot_id!r}")
    if len(zone.description) > MAX_DESCRIPTION_CHARS:
        raise ContractError(f"zone description is longer than {MAX_DESCRIPTION_CHARS} characters")
    problem = polygon_problem(zone.xs, zone.ys)
    if problem is not None:
        raise ContractError(f"zone {problem}")


def parse_polygon(text: str, field: str = "--polygon") -> tuple[tuple[float, ...], ...]:
    """``"x,y; x,y; x,y"`` -> ((xs...), (ys...)); ContractError naming ``field``. Checks the
    text only: :func:`polygon_problem` judges the polygon."""
    if len(text) > 20 * MAX_VERTICES * 2:
        raise ContractError(f"{field} is too long: at most {MAX_VERTICES} vertices")
    xs: list[float] = []
    ys: list[float] = []
    for i, chunk in enumerate((c for c in text.split(";") if c.strip()), start=1):
        parts = chunk.split(",")
        if len(parts) != 2:
            raise ContractError(f"{field} vertex {i} must be 'x,y', got {chunk.strip()!r}")
        try:
            x, y = float(parts[0]), float(parts[1])
        except ValueError:
            raise ContractError(
                f"{field} vertex {i} must be two numbers 'x,y', got {chunk.strip()!r}"
            ) from None
        xs.append(x)
        ys.append(y)
    return tuple(xs), tuple(ys)


async def read_zones(db: Database) -> list[Zone]:
    """Every zone, by name."""
    return [Zone.of_row(r) for r in await db.fetch(READ_SQL)]


async def add_zone(db: Database, zone: Zone) -> None:
    """Insert ``zone`` and notify ``pnav/db/zone/_`` (a unique name: an existing zone is
    removed first). The database refuses what :func:`check_zone` would."""
    await db.write(
        keys.ZONE,
        None,
        INSERT_SQL,
        zone.name,
        zone.kind,
        list(zone.xs),
        list(zone.ys),
        zone.max_speed_mps,
        zone.robot_id,
        zone.description,
    )


async def remove_zone(db: Database, name: str) -> bool:
    """Delete the zone named ``name`` and notify; whether there was one (none: nothing
    changed, nothing notified)."""
    async with db.transaction() as tx:
        removed = await tx.conn.fetchval(DELETE_SQL, name)
        if removed is not None:
            tx.changed(keys.ZONE, None)
    return removed is not None

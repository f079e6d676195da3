"""Moving obstacles of a world file: a shape that travels a path at a constant speed.

A world file's ``movers`` (format in docs/SIM.md)::

    movers:
      - {name: walker, type: cylinder, radius: 0.25, path: [[1, 2], [6, 2]], speed: 0.8,
         mode: back_and_forth}
      - {name: cart, type: box, size: [0.8, 0.5, 1.0], path: [[1, 1], [5, 1], [5, 4]],
         speed: 1.2, mode: loop, offset: 2.0}

A mover's place is a function of sim time alone (:meth:`MoverSpec.pose_at`): ``offset`` metres
along its path at time 0, then ``speed`` m/s along it; ``loop`` runs the path as a closed
polygon (the last point back to the first), ``back_and_forth`` runs it to its end and back.
A box faces along the segment it travels. Nothing pushes a mover and a mover pushes nothing:
it passes through whatever is in its way, as a scripted person or forklift that does not
yield would. The lidar and the sim's contact test see movers; the map does not.

Every field is checked at the door: a bad value is one WorldError naming the file, the
mover and the field.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

from common.errors import WorldError
from services.sim.entry import EntryReader

MODES = ("loop", "back_and_forth")
# far beyond a person (1.5 m/s) or a warehouse vehicle (about 3 m/s): a larger value is a typo
MAX_SPEED_MPS = 10.0
MAX_MOVERS = 100
MAX_PATH_POINTS = 1000
MAX_COORDINATE_M = 100_000.0  # the contract's bound on a position (CONTRACT.md, goal_xy_bounded)
MAX_SIZE_M = 50.0  # of a mover's body, any extent
DEFAULT_HEIGHT_M = 1.0  # above every shipped lidar's mount
_COMMON = ("name", "type", "path", "speed", "mode", "offset")
MOVER_KEYS = {
    "cylinder": (*_COMMON, "radius", "height"),
    "circle": (*_COMMON, "radius", "height"),
    "box": (*_COMMON, "size"),
}

Point = tuple[float, float]


@dataclass(frozen=True)
class MoverSpec:
    name: str
    shape: str  # "box" or "cylinder"
    # box: full extents (along its travel, across, up); cylinder: 2r, 2r, height
    size: tuple[float, float, float]
    path: tuple[Point, ...]
    speed_mps: float
    mode: str = "loop"
    offset_m: float = 0.0

    @property
    def radius_m(self) -> float:
        """A cylinder's radius; a box's circumscribed one (its reach from its centre)."""
        if self.shape == "cylinder":
            return self.size[0] / 2.0
        return math.hypot(self.size[0], self.size[1]) / 2.0

    @cached_property
    def segments(self) -> tuple[tuple[Point, Point, float], ...]:
        """The legs it travels, in order (``loop``: the closing one too), each with its
        length; none of zero length."""
        pts = self.path
        legs = list(itertools.pairwise(pts))
        if self.mode == "loop":
            legs.append((pts[-1], pts[0]))
        return tuple((a, b, math.dist(a, b)) for a, b in legs if a != b)

    @cached_property
    def length_m(self) -> float:
        """One way along the path (``loop``: once round)."""
        return sum(leg for _, _, leg in self.segments)

    @property
    def period_s(self) -> float:
        """Sim seconds until it is back where it started, moving the same way."""
        one_way = self.length_m / self.speed_mps
        return one_way if self.mode == "loop" else 2.0 * one_way

    def pose_at(self, t: float) -> tuple[float, float, float]:
        """(x, y, heading) at sim time ``t``: heading is the direction it travels, rad."""
        length = self.length_m
        cycle = length if self.mode == "loop" else 2.0 * length
        s = math.fmod(self.offset_m + self.speed_mps * t, cycle)
        if s < 0.0:  # a negative offset
            s += cycle
        backward = s > length  # back_and_forth, on the way back
        if backward:
            s = cycle - s
        last = len(self.segments) - 1
        for k, (a, b, leg) in enumerate(self.segments):
            if s <= leg or k == last:
                f = min(s / leg, 1.0)
                ux, uy = (b[0] - a[0]) / leg, (b[1] - a[1]) / leg
                heading = math.atan2(-uy, -ux) if backward else math.atan2(uy, ux)
                return a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f, heading
            s -= leg
        raise AssertionError("unreachable: a mover's path has at least one leg")

    def overlaps_disc(self, t: float, x: float, y: float, radius: float) -> bool:
        """Whether a disc at (x, y) overlaps this mover at sim time ``t``."""
        mx, my, heading = self.pose_at(t)
        dx, dy = x - mx, y - my
        if self.shape == "cylinder":
            return math.hypot(dx, dy) < radius + self.size[0] / 2.0
        c, s = math.cos(-heading), math.sin(-heading)
        lx, ly = c * dx - s * dy, s * dx + c * dy
        qx = max(abs(lx) - self.size[0] / 2.0, 0.0)
        qy = max(abs(ly) - self.size[1] / 2.0, 0.0)
        return math.hypot(qx, qy) < radius

    def message(self) -> dict[str, Any]:
        """This mover in the ``pnav/sim/world`` message (CONTRACT.md): enough to draw it."""
        return {
            "name": self.name,
            "type": self.shape,
            "size": list(self.size),
            "path": [[x, y] for x, y in self.path],
            "speed_mps": self.speed_mps,
            "mode": self.mode,
            "offset_m": self.offset_m,
        }


def parse_movers(path: Path, docs: list[Any]) -> tuple[MoverSpec, ...]:
    """A world file's ``movers`` list, every entry checked."""
    if len(docs) > MAX_MOVERS:
        raise WorldError(f"{path}: movers: at most {MAX_MOVERS} movers, got {len(docs)}")
    return tuple(_mover(path, i, doc) for i, doc in enumerate(docs))


def _mover(path: Path, i: int, doc: Any) -> MoverSpec:
    r = EntryReader(path, doc, f"movers[{i}]")
    shape = r.doc.get("type", "cylinder")
    if shape not in MOVER_KEYS:
        raise r.error(f"'type' must be cylinder (or circle) or box, got {shape!r}")
    r.only(MOVER_KEYS[shape], f": a {shape} mover has no such key")
    name = r.ident("name", f"mover_{i}")
    if shape == "box":
        size = r.doc.get("size")
        if (
            not isinstance(size, list)
            or len(size) not in (2, 3)
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in size)
            or not all(math.isfinite(v) and 0 < v <= MAX_SIZE_M for v in size)
        ):
            raise r.error(
                f"'size' must be [along, across] or [along, across, height] of numbers in "
                f"(0, {MAX_SIZE_M:g}] m, got {size!r}"
            )
        sx, sy, *rest = (float(v) for v in size)
        dims = (sx, sy, rest[0] if rest else DEFAULT_HEIGHT_M)
    else:
        radius, height = r.positive("radius"), r.positive("height", DEFAULT_HEIGHT_M)
        if radius > MAX_SIZE_M / 2 or height > MAX_SIZE_M:
            raise r.error(f"'radius' and 'height' must be at most {MAX_SIZE_M:g} m across")
        dims, shape = (2 * radius, 2 * radius, height), "cylinder"
    speed = r.positive("speed")
    if speed > MAX_SPEED_MPS:
        raise r.error(f"'speed' must be at most {MAX_SPEED_MPS:g} m/s, got {speed}")
    mode = r.doc.get("mode", "loop")
    if mode not in MODES:
        raise r.error(f"'mode' must be loop or back_and_forth, got {mode!r}")
    offset = r.number("offset", 0.0)
    if abs(offset) > MAX_COORDINATE_M:
        raise r.error(f"'offset' must be within +-{MAX_COORDINATE_M:g} m, got {offset}")
    spec = MoverSpec(name, shape, dims, _path(r), speed, str(mode), offset)
    if spec.length_m <= 0.0:
        raise r.error("'path' must have some length (its points are all the same)")
    return spec


def _path(r: EntryReader) -> tuple[Point, ...]:
    points = r.doc.get("path")
    if points is None:
        raise r.error("missing required key 'path' (a list of [x, y] points, at least 2)")
    if not isinstance(points, list) or len(points) < 2:
        raise r.error(f"'path' must list at least 2 points [x, y], got {points!r}")
    if len(points) > MAX_PATH_POINTS:
        raise r.error(f"'path' must list at most {MAX_PATH_POINTS} points, got {len(points)}")
    out: list[Point] = []
    for k, p in enumerate(points):
        if (
            not isinstance(p, list)
            or len(p) != 2
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in p)
            or not all(math.isfinite(v) and abs(v) <= MAX_COORDINATE_M for v in p)
        ):
            raise r.error(
                f"'path'[{k}] must be [x, y] of finite numbers within +-{MAX_COORDINATE_M:g} m, "
                f"got {p!r}"
            )
        out.append((float(p[0]), float(p[1])))
    return tuple(out)

"""How hard a world is to drive through, measured along its reference path (after BARN).

Perille et al. (2020) rank their worlds by metrics computed at the points of the shortest
path; these are the same ideas on our grids. Every metric is sampled every ``step_m`` along
the part of the reference path inside the obstacle field (the empty start and goal zones
would only dilute it), except tortuosity, which takes the whole path:

- ``closest_obstacle_m``: mean distance from a path point to the nearest occupied cell.
  Lower is harder: less room to be wrong.
- ``avg_visibility_m``: mean length of ``rays`` rays cast all round each point, each cut at
  the first occupied cell or at ``visibility_range_m`` (the lidar's range). Lower is harder:
  the robot sees less of what is coming.
- ``dispersion``: mean number of switches, going once round the circle of rays, between a
  ray that meets an obstacle within ``dispersion_range_m`` and one that does not. Higher is
  harder: more gaps to choose between.
- ``characteristic_dimension_m``: mean over the points of the narrowest "width" there: the
  smallest, over all axes, of the two opposite rays' lengths added. Lower is harder.
- ``tortuosity``: reference path length over the straight start-goal distance. Higher is
  harder: more turning.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from pnav.bench.nav.search import BoolGrid, Point, polyline_length

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class DifficultySettings:
    step_m: float = 0.1  # spacing of the sample points along the path
    rays: int = 72  # every 5 degrees; an even count, so every ray has its opposite
    visibility_range_m: float = 3.5  # the LDS-01's range
    dispersion_range_m: float = 1.0  # about one robot-second of driving and a half


@dataclass(frozen=True)
class Difficulty:
    closest_obstacle_m: float
    avg_visibility_m: float
    dispersion: float
    characteristic_dimension_m: float
    tortuosity: float

    def to_json(self) -> dict[str, float]:
        return {k: round(v, 4) for k, v in asdict(self).items()}

    @staticmethod
    def from_json(doc: dict[str, Any]) -> Difficulty:
        return Difficulty(**{k: float(doc[k]) for k in Difficulty.__dataclass_fields__})


# "lower is harder" for these; the rest are "higher is harder"
LOWER_IS_HARDER = ("closest_obstacle_m", "avg_visibility_m", "characteristic_dimension_m")


def resample(points: Sequence[Point], step_m: float) -> FloatArray:
    """Points every ``step_m`` along a polyline, both ends included; shape (n, 2)."""
    pts = np.asarray(points, dtype=np.float64)
    seg = np.hypot(*np.diff(pts, axis=0).T)
    along = np.concatenate(([0.0], np.cumsum(seg)))
    total = float(along[-1])
    s = np.linspace(0.0, total, max(2, math.ceil(total / step_m) + 1))
    return np.column_stack((np.interp(s, along, pts[:, 0]), np.interp(s, along, pts[:, 1])))


def clearance(occupied: BoolGrid, resolution: float, origin: Point, pts: FloatArray) -> FloatArray:
    """Distance from each point to the nearest occupied cell's square (0 inside one)."""
    rows, cols = np.nonzero(occupied)
    if rows.size == 0:
        return np.full(len(pts), math.inf)
    x0 = origin[0] + cols * resolution
    y0 = origin[1] + rows * resolution
    px, py = pts[:, 0:1], pts[:, 1:2]
    dx = np.maximum(np.maximum(x0 - px, px - (x0 + resolution)), 0.0)
    dy = np.maximum(np.maximum(y0 - py, py - (y0 + resolution)), 0.0)
    result: FloatArray = np.sqrt(dx * dx + dy * dy).min(axis=1)
    return result


def ray_lengths(
    occupied: BoolGrid,
    resolution: float,
    origin: Point,
    pts: FloatArray,
    rays: int,
    max_range_m: float,
) -> FloatArray:
    """Free length of ``rays`` rays round each point (ray 0 along +x, counter-clockwise),
    marched in half-cell steps and capped at ``max_range_m``; shape (points, rays). Leaving
    the map counts as a hit."""
    step = resolution / 2.0
    dist = np.arange(1, math.ceil(max_range_m / step) + 1) * step
    angles = np.arange(rays) * (2.0 * math.pi / rays)
    xs = pts[:, 0, None, None] + np.cos(angles)[None, :, None] * dist[None, None, :]
    ys = pts[:, 1, None, None] + np.sin(angles)[None, :, None] * dist[None, None, :]
    cols = np.floor((xs - origin[0]) / resolution).astype(np.int64)
    rws = np.floor((ys - origin[1]) / resolution).astype(np.int64)
    height, width = occupied.shape
    inside = (rws >= 0) & (rws < height) & (cols >= 0) & (cols < width)
    hit = ~inside
    hit[inside] = occupied[rws[inside], cols[inside]]
    first = np.argmax(hit, axis=2)
    lengths = np.where(hit.any(axis=2), dist[first] - step / 2.0, max_range_m)
    result: FloatArray = np.minimum(lengths, max_range_m)
    return result


def measure(
    occupied: BoolGrid,
    resolution: float,
    origin: Point,
    path: Sequence[Point],
    field_y: tuple[float, float],
    settings: DifficultySettings | None = None,
) -> Difficulty:
    """The difficulty metrics of a world (see the module docstring); ``field_y`` is the
    obstacle field's band (y from, y to) in world metres."""
    cfg = settings or DifficultySettings()
    pts = resample(path, cfg.step_m)
    in_field = (pts[:, 1] >= field_y[0]) & (pts[:, 1] <= field_y[1])
    if in_field.any():
        pts = pts[in_field]
    closest = clearance(occupied, resolution, origin, pts)
    seen = ray_lengths(occupied, resolution, origin, pts, cfg.rays, cfg.visibility_range_m)
    # the narrowest axis: each ray and its opposite, which is half a turn further on
    half = cfg.rays // 2
    widths = seen[:, :half] + seen[:, half : 2 * half]
    near = seen < cfg.dispersion_range_m
    switches = (near != np.roll(near, 1, axis=1)).sum(axis=1)
    straight = math.dist(path[0], path[-1])
    return Difficulty(
        closest_obstacle_m=float(closest.mean()),
        avg_visibility_m=float(seen.mean()),
        dispersion=float(switches.mean()),
        characteristic_dimension_m=float(widths.min(axis=1).mean()),
        tortuosity=polyline_length(path) / straight if straight > 0 else 1.0,
    )

"""The lidar of every robot that scans in a physics step, cast together in closed form: the
walls and obstacles as the world's outline (services/sim/outline.py), the other robots as the
upright cylinders they are.

A beam is a horizontal ray from its robot's centre at the lidar's height. It meets a body
only if that height is within the body's (from the floor to its top), and then where it
first crosses one of the body's faces or enters its disc. For each scanning robot and each
face or disc within its reach that rises to its beams (and, for a face, is turned towards
it), the beams within the shape's angular extent as seen from the robot are found, and only
those are tested exactly; each beam keeps its nearest meeting. A robot's own body is never
in the way of its own beams, and every other robot's is.

Why not Bullet's ray test (the sim cast the walls and obstacles with it until 2026-11-25):
a ray costs pybullet about 0.4 us in call overhead alone, whatever it meets, and the fleet
casts hundreds of thousands a second (docs/BENCHMARKS.md, seventh round). Bullet stays the
yardstick in the tests (tests/unit/sim/test_fleetcast.py): the walls' mesh agrees to
rounding; its convex shapes (boxes, cylinders) only to a few mm near their edges, where its
convex cast is approximate and this is exact.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from common.robotmodel import RobotModel
from services.sim.lidar import FloatArray, Lidar
from services.sim.outline import Outline, spans

Pose = tuple[float, float, float]
Cast = tuple[npt.NDArray[np.bool_], npt.NDArray[np.float64]]
IntArray = npt.NDArray[np.intp]

# beams of slack each side of a shape's angular extent, against rounding in the angles (the
# beams within are then tested exactly)
SLACK_BEAMS = 0.5
TWO_PI = 2.0 * np.pi
# how far past a face's ends (a fraction of its length) a beam still meets it: a beam through
# a corner meets the solid there, whichever face's rounding it falls on
CORNER = 1e-9


class FleetCast:
    """Casts the lidars of a fleet (robot i: ``models[i]``'s body, ``lidars[i]``) in a world
    whose static part is ``outline``."""

    def __init__(
        self, outline: Outline, models: Sequence[RobotModel], lidars: Sequence[Lidar]
    ) -> None:
        self.outline = outline
        n = len(models)
        # every disc: the outline's, then one per robot (its owner's index; -1: static)
        self.radius = np.concatenate([outline.radius, [m.footprint_radius_m for m in models]])
        self.top = np.concatenate([outline.disc_top, [m.height_m for m in models]])
        self.owner = np.concatenate([np.full(len(outline.radius), -1), np.arange(n)])
        self.beams = np.array([lidar.params.beams for lidar in lidars], dtype=np.intp)
        inc = np.array([lidar.params.angle_increment for lidar in lidars])
        # a one-beam partial lidar has no increment: any width stands in (windows only choose
        # which beams to test; the test is exact)
        self.increment = np.where(inc > 0.0, inc, TWO_PI)
        self.range_max = np.array([lidar.params.range_max_m for lidar in lidars])
        self.angle_min = np.array([lidar.params.angle_min_rad for lidar in lidars])
        self.full = np.array([lidar.params.full_turn for lidar in lidars], dtype=bool)
        self.beam_z = np.array([lidar.height for lidar in lidars])
        # every distinct lidar's beam directions (from the heading) in one table: robot i's
        # beam b is entry table[i] + b
        offset: dict[int, int] = {}
        parts: list[Lidar] = []
        for lidar in lidars:
            if id(lidar) not in offset:
                offset[id(lidar)] = sum(p.params.beams for p in parts)
                parts.append(lidar)
        self.table = np.array([offset[id(lidar)] for lidar in lidars], dtype=np.intp)
        self.cos = np.concatenate([p.cos for p in parts]) if parts else np.empty(0)
        self.sin = np.concatenate([p.sin for p in parts]) if parts else np.empty(0)
        self.face_e = outline.b - outline.a
        self.face_length2 = np.maximum(np.sum(self.face_e**2, axis=1), 1e-300)

    def __call__(self, poses: Sequence[Pose], scanning: Sequence[int]) -> list[Cast]:
        """(hit, fraction along the ray) per beam of each robot in ``scanning`` (indices into
        ``poses``), in that order; fraction 1.0 where a beam meets nothing."""
        if not scanning:
            return []
        index = np.asarray(scanning, dtype=np.intp)
        first = np.concatenate([[0], np.cumsum(self.beams[index])])  # each one's first ray
        xy = np.array([(x, y) for x, y, _ in poses]).reshape(-1, 2)
        yaw = np.array([poses[i][2] for i in scanning])
        # every shape that may meet a scanner's beams, faces first: its scanner (a position
        # in ``index``), which one, and its angular extent from the scanner
        fk, face, f_bearing, f_half = self._faces(index, xy[index])
        dk, disc, dist, d_bearing, d_half = self._discs(index, xy)
        k = np.concatenate([fk, dk])
        aim = yaw[k] + self.angle_min[index[k]]  # beam 0's direction
        bearing = np.concatenate([f_bearing, d_bearing]) - aim
        src, beam, off = self._windows(index, k, bearing, np.concatenate([f_half, d_half]))
        ray = first[k[src]] + beam
        on_face = src < len(fk)
        # the faces: each candidate beam's ray, from its scanner's centre to its range's end
        f_src = src[on_face]
        scanner = fk[f_src]
        d = self._rays(index[scanner], beam[on_face], yaw[scanner])
        f_met, f_along = self._cross(face[f_src], xy[index[scanner]], d)
        # the discs
        d_src = src[~on_face] - len(fk)
        reach = self.range_max[index[dk[d_src]]]
        d_met, d_along = _enter(dist[d_src], self.radius[disc[d_src]], off[~on_face], reach)
        fraction = np.full(first[-1], np.inf)
        met = np.concatenate([ray[on_face][f_met], ray[~on_face][d_met]])
        np.minimum.at(fraction, met, np.concatenate([f_along, d_along]))
        hit = fraction <= 1.0  # a meeting at the very end of a ray is one (as in Bullet)
        fraction[~hit] = 1.0
        return [(hit[a:b], fraction[a:b]) for a, b in itertools.pairwise(first.tolist())]

    def _rays(self, robot: IntArray, beam: IntArray, yaw: FloatArray) -> FloatArray:
        """Each robot's beam as a vector, from its centre to its range's end, the robot
        heading ``yaw``."""
        t = self.table[robot] + beam
        c, s = np.cos(yaw), np.sin(yaw)
        cos, sin = self.cos[t], self.sin[t]
        ray: FloatArray = np.stack([cos * c - sin * s, sin * c + cos * s], axis=1)
        ray *= self.range_max[robot][:, None]
        return ray

    def _faces(
        self, index: IntArray, origin: FloatArray
    ) -> tuple[IntArray, IntArray, FloatArray, FloatArray]:
        """The outline's faces turned towards each scanner, within its reach and as tall as
        its beams: (scanner, face, bearing of the face's middle direction, half its angular
        width), angles in rad in the world's frame."""
        out = self.outline
        k, f = out.near(origin, self.range_max[index])
        rel = origin[k] - out.a[f]  # the scanner from each face's start
        e = self.face_e[f]
        # turned towards the scanner (it is on the free side, the face's left), within reach
        facing = e[:, 0] * rel[:, 1] - e[:, 1] * rel[:, 0] > 0.0
        along = (rel[:, 0] * e[:, 0] + rel[:, 1] * e[:, 1]) / self.face_length2[f]
        gap = rel - np.clip(along, 0.0, 1.0)[:, None] * e
        near = gap[:, 0] ** 2 + gap[:, 1] ** 2 <= self.range_max[index[k]] ** 2
        tall = self.beam_z[index[k]] <= out.face_top[f]
        keep = facing & near & tall
        k, f = k[keep], f[keep]
        # the face's angular extent from the scanner, under half a turn (it faces the scanner)
        to_a, to_b = out.a[f] - origin[k], out.b[f] - origin[k]
        phi_a = np.arctan2(to_a[:, 1], to_a[:, 0])
        half = np.mod(np.arctan2(to_b[:, 1], to_b[:, 0]) - phi_a, TWO_PI) / 2.0
        return k, f, phi_a + half, half

    def _cross(
        self, face: IntArray, start: FloatArray, d: FloatArray
    ) -> tuple[npt.NDArray[np.bool_], FloatArray]:
        """Whether each ray start + s d crosses its face a + u e from the free side, s in
        [0, 1) and u in [0, 1], and the s of those that do."""
        w = self.outline.a[face] - start
        e = self.face_e[face]
        denom = d[:, 0] * e[:, 1] - d[:, 1] * e[:, 0]
        safe = np.where(denom > 0.0, denom, 1.0)
        s = (w[:, 0] * e[:, 1] - w[:, 1] * e[:, 0]) / safe
        u = (w[:, 0] * d[:, 1] - w[:, 1] * d[:, 0]) / safe
        met = (denom > 0.0) & (s >= 0.0) & (s < 1.0) & (u >= -CORNER) & (u <= 1.0 + CORNER)
        return met, s[met]

    def _discs(
        self, index: IntArray, xy: FloatArray
    ) -> tuple[IntArray, IntArray, FloatArray, FloatArray, FloatArray]:
        """The discs (cylinder obstacles, the other robots) within each scanner's reach and as
        tall as its beams: (scanner, disc, distance between the centres, bearing of the disc's
        centre, half its angular width), angles in rad in the world's frame."""
        centres = np.concatenate([self.outline.centre, xy])
        offsets = centres[None, :, :] - xy[index][:, None, :]
        dist = np.hypot(offsets[..., 0], offsets[..., 1])
        near = dist <= (self.range_max[index][:, None] + self.radius[None, :])
        near &= self.owner[None, :] != index[:, None]  # not its own body
        near &= self.beam_z[index][:, None] <= self.top[None, :]
        k, j = np.nonzero(near)
        radius, d = self.radius[j], dist[k, j]
        bearing = np.arctan2(offsets[k, j, 1], offsets[k, j, 0])
        # a disc round the beams' origin (never so far: bodies do not overlap) meets them all
        half = np.where(d > radius, np.arcsin(np.minimum(1.0, radius / np.maximum(d, 1e-12))), 4.0)
        return k, j, d, bearing, half

    def _windows(
        self, index: IntArray, k: IntArray, bearing: FloatArray, half: FloatArray
    ) -> tuple[IntArray, IntArray, FloatArray]:
        """Every (window, beam) with the beam within ``half`` (rad, plus SLACK_BEAMS) of the
        window's ``bearing`` from scanner k's beam 0: the window, the beam (an index into
        the scanner's beams) and the beam's angle from the bearing."""
        robot = index[k]
        full = self.full[robot]
        n, inc = self.beams[robot], self.increment[robot]
        # A full turn's beams wrap round (index mod beams). A partial field of view's beams
        # span [0, fov] from beam 0: the bearing is taken in [0, 2 pi) and looked for one
        # turn either side too, so a shape straddling beam 0's direction is found at both ends.
        if full.all():
            src, centre_rad = np.arange(len(k)), bearing
        else:
            # the window each copy looks for, and the turn (-1, 0, 1) it looks in
            src, turn = spans(np.where(full, 0, -1), np.where(full, 1, 3))
            base = np.where(full, bearing, np.mod(bearing, TWO_PI))
            centre_rad = base[src] + turn * TWO_PI
            full, n, inc = full[src], n[src], inc[src]
        centre = centre_rad / inc  # in beams
        spread = half[src] / inc + SLACK_BEAMS
        lo = np.ceil(centre - spread).astype(np.intp)
        hi = np.floor(centre + spread).astype(np.intp)
        # a full turn's window covers each beam once at most; a partial field of view's
        # beams past either end do not exist
        hi = np.where(full, np.minimum(hi, lo + n - 1), np.minimum(hi, n - 1))
        lo = np.where(full, lo, np.maximum(lo, 0))
        which, beam = spans(lo, np.maximum(hi - lo + 1, 0))  # every (copy, beam) within
        off = beam * inc[which] - centre_rad[which]
        return src[which], beam % n[which], off


def _enter(
    d: FloatArray, r: FloatArray, off: FloatArray, reach: FloatArray
) -> tuple[npt.NDArray[np.bool_], FloatArray]:
    """Whether a beam at angle ``off`` from the direction of a disc of radius r whose centre
    lies d away meets it within ``reach``, and how far along the ray (a fraction of reach).

    The beam's line passes d |sin(off)| from the centre and enters the disc at d cos(off) -
    sqrt(r^2 - across^2) along it; a beam that starts inside the disc meets it at once."""
    across = d * np.abs(np.sin(off))
    entry = d * np.cos(off) - np.sqrt(np.maximum(0.0, r * r - across * across))
    inside = d <= r
    met = inside | ((across <= r) & (entry >= 0.0) & (entry <= reach))
    return met, (np.where(inside, 0.0, entry) / reach)[met]

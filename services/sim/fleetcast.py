"""The lidar of every robot that scans in a physics step, cast together in closed form: the
walls and obstacles as the world's outline (services/sim/outline.py), the other robots as the
upright cylinders or polygon prisms their footprints are (common/footprint.py).

A beam is a horizontal ray from its robot's centre at the lidar's height. It meets a body
only if that height is within the body's (from the floor to its top), and then where it
first crosses one of the body's faces or enters its disc (a robot with a footprint polygon
is its faces, placed where the robot stands at each cast). For each scanning robot and each
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
        # every disc: the outline's, then one per round robot (its owner's index; -1: static)
        round_ = [i for i, m in enumerate(models) if m.footprint.is_disc]
        self.round = np.array(round_, dtype=np.intp)
        self.radius = np.concatenate(
            [outline.radius, [models[i].footprint_radius_m for i in round_]]
        )
        self.top = np.concatenate([outline.disc_top, [models[i].height_m for i in round_]])
        self.owner = np.concatenate([np.full(len(outline.radius), -1), self.round])
        # every face of the polygon robots, in their own frames, turned so that the outside
        # is on the left as the outline's faces are: (start, end, owner, top)
        starts, ends, owners, tops = [], [], [], []
        for i, m in enumerate(models):
            if m.footprint.is_disc:
                continue
            v = m.footprint.vertices
            starts.append(np.roll(v, -1, axis=0))  # a counter-clockwise edge reversed
            ends.append(v)
            owners.append(np.full(len(v), i, dtype=np.intp))
            tops.append(np.full(len(v), m.height_m))
        self.body_a = np.concatenate(starts) if starts else np.empty((0, 2))
        self.body_b = np.concatenate(ends) if ends else np.empty((0, 2))
        self.body_owner = np.concatenate(owners) if owners else np.empty(0, dtype=np.intp)
        self.body_top = np.concatenate(tops) if tops else np.empty(0)
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
        fk, fa, fe, f_bearing, f_half = self._faces(index, xy[index], xy, yaw_all(poses))
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
        f_met, f_along = _cross(fa[f_src], fe[f_src], xy[index[scanner]], d)
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
        self, index: IntArray, origin: FloatArray, xy: FloatArray, yaws: FloatArray
    ) -> tuple[IntArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """The faces (the outline's, then the polygon robots' where they stand) turned
        towards each scanner, within its reach and as tall as its beams: (scanner, face start,
        face vector, bearing of the face's middle direction, half its angular width), angles
        in rad in the world's frame."""
        out = self.outline
        k, f = out.near(origin, self.range_max[index])
        a, e, top = out.a[f], self.face_e[f], out.face_top[f]
        if len(self.body_owner):
            # every scanner against every other robot's faces (few: a handful per robot)
            owner = self.body_owner
            c, s = np.cos(yaws[owner]), np.sin(yaws[owner])
            ba = xy[owner] + _turn(self.body_a, c, s)
            be = xy[owner] + _turn(self.body_b, c, s) - ba
            kk, j = np.nonzero(owner[None, :] != index[:, None])
            k = np.concatenate([k, kk])
            a = np.concatenate([a, ba[j]])
            e = np.concatenate([e, be[j]])
            top = np.concatenate([top, self.body_top[j]])
        rel = origin[k] - a  # the scanner from each face's start
        # turned towards the scanner (it is on the free side, the face's left), within reach
        facing = e[:, 0] * rel[:, 1] - e[:, 1] * rel[:, 0] > 0.0
        length2 = np.maximum(np.sum(e**2, axis=1), 1e-300)
        along = (rel[:, 0] * e[:, 0] + rel[:, 1] * e[:, 1]) / length2
        gap = rel - np.clip(along, 0.0, 1.0)[:, None] * e
        near = gap[:, 0] ** 2 + gap[:, 1] ** 2 <= self.range_max[index[k]] ** 2
        tall = self.beam_z[index[k]] <= top
        keep = facing & near & tall
        k, a, e = k[keep], a[keep], e[keep]
        # the face's angular extent from the scanner, under half a turn (it faces the scanner)
        to_a, to_b = a - origin[k], a + e - origin[k]
        phi_a = np.arctan2(to_a[:, 1], to_a[:, 0])
        half = np.mod(np.arctan2(to_b[:, 1], to_b[:, 0]) - phi_a, TWO_PI) / 2.0
        return k, a, e, phi_a + half, half

    def _discs(
        self, index: IntArray, xy: FloatArray
    ) -> tuple[IntArray, IntArray, FloatArray, FloatArray, FloatArray]:
        """The discs (cylinder obstacles, the other robots) within each scanner's reach and as
        tall as its beams: (scanner, disc, distance between the centres, bearing of the disc's
        centre, half its angular width), angles in rad in the world's frame."""
        centres = np.concatenate([self.outline.centre, xy[self.round]])
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


def yaw_all(poses: Sequence[Pose]) -> FloatArray:
    return np.array([yaw for _, _, yaw in poses], dtype=np.float64)


def _turn(v: FloatArray, c: FloatArray, s: FloatArray) -> FloatArray:
    """Points ``v`` (robot frame, one per row) turned by each row's (cos, sin)."""
    out: FloatArray = np.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]], axis=1)
    return out


def _cross(
    a: FloatArray, e: FloatArray, start: FloatArray, d: FloatArray
) -> tuple[npt.NDArray[np.bool_], FloatArray]:
    """Whether each ray start + s d crosses its face a + u e from the free side, s in
    [0, 1) and u in [0, 1], and the s of those that do."""
    w = a - start
    denom = d[:, 0] * e[:, 1] - d[:, 1] * e[:, 0]
    safe = np.where(denom > 0.0, denom, 1.0)
    s = (w[:, 0] * e[:, 1] - w[:, 1] * e[:, 0]) / safe
    u = (w[:, 0] * d[:, 1] - w[:, 1] * d[:, 0]) / safe
    met = (denom > 0.0) & (s >= 0.0) & (s < 1.0) & (u >= -CORNER) & (u <= 1.0 + CORNER)
    return met, s[met]


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

"""The lidar of every robot that scans in a physics step: the walls and obstacles in one
batched Bullet ray cast, the other robots met exactly, as the cylinders they are.

A robot's beams start at its centre, inside its own body, and no robot's body may stand in
the way of its own beams, while every other robot's must. pybullet cannot leave a body out
per ray (see ``Scene.cast_from``), and a ray tested against a robot's cylinder costs Bullet an
iterative convex cast, several times a ray against the walls' mesh. So the cast takes two
steps:

1. All the beams of all the scanning robots go in one ``rayTestBatch`` in a second pybullet
   client holding the same walls and obstacles and no robot (the static scene, built from
   the same world): each beam's first hit on them, exactly as Bullet gives it.
2. The other robots are met in closed form. A robot's body is an upright cylinder and a beam
   is a horizontal ray, so a beam meets it where the ray enters the body's disc, if the beam's
   height is within the body's. Only the beams within a robot's angular extent, seen from the
   scanner, are tested; the nearest robot met before the static hit replaces that hit.

Why not Bullet for the robots too: besides the cost (with robots in each other's reach, most
of the lidar's: docs/BENCHMARKS.md, sixth round), Bullet's convex cast against a cylinder is
approximate. Against the exact entry point it reads 0.1 mm short at the median, 1.4 mm short
for one beam in twenty and 3.5 mm for one in a hundred, and it reports hits on beams that
pass up to a few mm outside the body (tests/unit/sim/test_fleetcast.py measures both). The
closed form is the cylinder the world file describes; the static scene stays Bullet's (the
walls' mesh is tested exactly).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from services.sim.lidar import FloatArray, Lidar
from services.sim.physics import Scene

Pose = tuple[float, float, float]
Cast = tuple[npt.NDArray[np.bool_], npt.NDArray[np.float64]]
IntArray = npt.NDArray[np.intp]

# beams of slack each side of a robot's angular extent, against rounding in the angles (the
# beams within are then tested exactly)
SLACK_BEAMS = 0.5


@dataclass(frozen=True)
class _Pairs:
    """Every (scanning robot, other robot) pair within reach of the scanner's beams, the other
    robot's body standing in the beams' plane."""

    k: IntArray  # the scanning robot's position in ``scanning``
    j: IntArray  # the other robot's index
    dist: FloatArray  # between their centres, m
    bearing: FloatArray  # of the other robot from the scanner's beam 0, rad


def cast_fleet(
    scene: Scene,
    static: Scene,
    lidars: Sequence[Lidar],
    poses: Sequence[Pose],
    scanning: Sequence[int],
) -> list[Cast]:
    """(hit, fraction) per beam of each robot in ``scanning`` (indices into ``poses`` and
    ``lidars``, robot i's lidar; ``scene`` has every robot, ``static`` the same world without
    them), in that order. Robots may carry different lidars (several models)."""
    if not scanning:
        return []
    mine = [lidars[i] for i in scanning]
    rays = [lidar.rays(*poses[i]) for lidar, i in zip(mine, scanning, strict=True)]
    starts, ends = rays[0]
    if len(rays) > 1:
        starts = np.concatenate([s for s, _ in rays])
        ends = np.concatenate([e for _, e in rays])
    first = np.cumsum([0, *(lidar.params.beams for lidar in mine)])  # each one's first ray
    range_max = np.array([lidar.params.range_max_m for lidar in mine])
    pairs = _reach(scene, poses, scanning, range_max + scene.max_radius, mine)
    # 1: the static scene
    hit, fraction = static.cast(starts, ends)
    # 2: the robots, nearer than the static hit
    ray, entry = _robot_hits(scene, pairs, mine, first)
    if len(ray):
        nearest = np.full(len(fraction), np.inf)
        np.minimum.at(nearest, ray, entry)
        nearest /= np.repeat(range_max, np.diff(first))
        met = nearest < fraction
        hit[met] = True
        fraction[met] = nearest[met]
    return [(hit[a:b], fraction[a:b]) for a, b in itertools.pairwise(first.tolist())]


def _reach(
    scene: Scene,
    poses: Sequence[Pose],
    scanning: Sequence[int],
    reach: FloatArray,
    lidars: Sequence[Lidar],
) -> _Pairs:
    """The pairs of a scanning robot and another robot within its ``reach`` whose body rises
    to the scanner's beams."""
    xy = np.array([(x, y) for x, y, _ in poses])
    offsets = xy[None, :, :] - xy[np.asarray(scanning)][:, None, :]
    dist = np.hypot(offsets[..., 0], offsets[..., 1])
    near = dist <= reach[:, None]
    near[np.arange(len(scanning)), np.asarray(scanning)] = False  # not its own body
    # a body lower than a lidar is below its beams' plane (as in Bullet's scene: a body
    # spans the floor to its height, the beams run at the lidar's height)
    tops = np.array([scene.height[b] for b in scene.robot_bodies])
    beam_z = np.array([lidar.height for lidar in lidars])
    near &= beam_z[:, None] <= tops[None, :]
    k, j = np.nonzero(near)
    yaw = np.array([poses[i][2] for i in scanning])[k]
    angle_min = np.array([lidar.params.angle_min_rad for lidar in lidars])[k]
    bearing = np.arctan2(offsets[k, j, 1], offsets[k, j, 0]) - yaw - angle_min
    return _Pairs(k, j, dist[k, j], bearing)


def _robot_hits(
    scene: Scene, pairs: _Pairs, lidars: Sequence[Lidar], first: IntArray
) -> tuple[IntArray, FloatArray]:
    """Every (beam, robot) meeting of the pairs: the beam (an index into the batch, scanner
    k's own starting at ``first[k]``) and how far along it the beam enters the robot's body,
    m (0 for a beam that starts inside it).

    A beam from the scanner's centre meets a disc of radius r whose centre lies D away only if
    its bearing is within asin(r / D) of the disc's; of those, the beams whose line passes
    within r of the centre, where they enter the disc at D cos(off) - sqrt(r^2 - across^2)."""
    if len(pairs.k) == 0:
        return np.empty(0, dtype=np.intp), np.empty(0)
    radii = np.array([scene.radius[b] for b in scene.robot_bodies])
    beams = np.array([lidar.params.beams for lidar in lidars])
    increments = np.array([lidar.params.angle_increment for lidar in lidars])
    reach = np.array([lidar.params.range_max_m for lidar in lidars])
    full = np.array([lidar.params.full_turn for lidar in lidars])[pairs.k]
    # A full turn's beams wrap round (index mod beams). A partial field of view's beams span
    # [0, fov] from beam 0: the disc's bearing is taken in [0, 2 pi) and looked for one turn
    # either side too, so a disc straddling beam 0's direction is found at both ends.
    copies = np.where(full, 1, 3)
    src = np.repeat(np.arange(len(copies)), copies)  # the pair each window looks for
    turn = np.arange(len(src)) - np.repeat(np.cumsum(copies) - copies, copies) - 1
    base = np.where(full, pairs.bearing, np.mod(pairs.bearing, 2.0 * np.pi))
    bearing = base[src] + np.where(full[src], 0.0, turn * 2.0 * np.pi)
    k, n, inc = pairs.k[src], beams[pairs.k[src]], increments[pairs.k[src]]
    radius, dist = radii[pairs.j[src]], pairs.dist[src]
    # a disc round the beams' origin (robots never overlap so far) would meet them all
    wide = np.arcsin(np.minimum(1.0, radius / np.maximum(dist, 1e-12))) / inc
    half = np.where(dist > radius, wide, n) + SLACK_BEAMS
    centre = bearing / inc  # in beams
    lo = np.ceil(centre - half).astype(np.intp)
    count = np.minimum(np.floor(centre + half).astype(np.intp) - lo + 1, n)
    # every (window, beam) within the windows' angular extents, flattened
    which = np.repeat(np.arange(len(count)), count)
    beam = lo[which] + np.arange(len(which)) - np.repeat(np.cumsum(count) - count, count)
    # beams past either end of a partial field of view do not exist
    exists = full[src[which]] | ((beam >= 0) & (beam < n[which]))
    which, beam = which[exists], beam[exists]
    # the beam's line passes ``across`` from the disc's centre, and enters it ``entry`` along
    off = beam * inc[which] - bearing[which]
    d, r = dist[which], radius[which]
    across = d * np.abs(np.sin(off))
    entry = d * np.cos(off) - np.sqrt(np.maximum(0.0, r * r - across * across))
    inside = d <= r
    meets = inside | ((across <= r) & (entry >= 0.0) & (entry <= reach[k[which]]))
    ray = first[k[which]] + beam % n[which]
    return ray[meets], np.where(inside, 0.0, entry)[meets]

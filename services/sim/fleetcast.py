"""The lidar of every robot that scans in a physics step, cast in one batched call, with
exactly the ranges each robot's own cast (``physics.Scene.cast_from``) gives, bit for bit.

A robot's beams start at its centre, inside its own body, so its body must be out of the way
of its own beams yet in place for every other robot's. pybullet cannot leave a body out per
ray (see ``Scene.cast_from``), so the cast takes two passes:

1. Every robot within reach of a scanning robot is lowered out of the beams' plane, and all
   the beams of all the scanning robots go in one ``rayTestBatch``: each beam's first hit on
   the walls and obstacles. That is the cheap part: a ray tested against a robot's cylinder
   costs several times a ray against the walls' mesh, and most beams meet no robot.
2. A beam whose line passes within a robot's radius (plus a margin) of another robot, nearer
   than its first static hit, may meet that robot first: it is cast again with those robots
   in place and its own robot lowered. The scanning robots whose beams need each other in
   place go in separate calls; usually one call serves them all.

Why it is exact: pybullet reports the closest hit, the smallest of the fractions at which the
ray meets each body, and each body's fraction depends only on the ray and that body (the
closest-hit bookkeeping only skips bodies that are farther). A body that cannot be met before
the closest hit thus changes nothing, present or not. A beam that is not cast again meets no
robot before its static hit; a beam cast again has every robot it may meet first in place.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from common.robotmodel import LidarModel
from services.sim.lidar import FloatArray, Lidar
from services.sim.physics import Scene

Pose = tuple[float, float, float]
Cast = tuple[npt.NDArray[np.bool_], npt.NDArray[np.float64]]
IntArray = npt.NDArray[np.intp]

# how far beyond a robot's radius a beam counts as maybe meeting it: pybullet's ray test
# against a cylinder stops within 1 mm of its surface (the GJK cast's tolerance), so a beam
# that close may report a hit; 1 cm is ten times that
GRAZE_M = 0.01
# beams of slack each side of a robot's angular extent, against rounding in the angles (the
# beams within are then tested exactly)
SLACK_BEAMS = 0.5


@dataclass
class _Recast:
    """The scanning robots whose flagged beams one call casts again."""

    owners: set[int] = field(default_factory=set)  # robot indices, lowered for the call
    needs: set[int] = field(default_factory=set)  # robots that must stand in place
    rays: list[IntArray] = field(default_factory=list)  # indices into the batch


@dataclass(frozen=True)
class _Pairs:
    """Every (scanning robot, other robot) pair within reach of each other's beams."""

    k: IntArray  # the scanning robot's position in ``scanning``
    j: IntArray  # the other robot's index
    dist: FloatArray  # between their centres, m
    bearing: FloatArray  # of the other robot from the scanner's beam 0, rad


def cast_fleet(
    scene: Scene, lidars: Sequence[Lidar], poses: Sequence[Pose], scanning: Sequence[int]
) -> list[Cast]:
    """(hit, fraction) per beam of each robot in ``scanning`` (indices into ``poses`` and
    ``lidars``, robot i's lidar; the scene has every robot), in that order, as
    ``scene.cast_from`` gives each. Robots may carry different lidars (several models)."""
    if not scanning:
        return []
    mine = [lidars[i] for i in scanning]
    rays = [lidar.rays(*poses[i]) for lidar, i in zip(mine, scanning, strict=True)]
    starts, ends = rays[0]
    if len(rays) > 1:
        starts = np.concatenate([s for s, _ in rays])
        ends = np.concatenate([e for _, e in rays])
    first = np.cumsum([0, *(lidar.params.beams for lidar in mine)])  # each one's first ray
    radii = np.array([scene.radius[b] for b in scene.robot_bodies]) + GRAZE_M
    range_max = np.array([lidar.params.range_max_m for lidar in mine])
    reach = range_max + scene.max_radius + GRAZE_M
    within, pairs = _reach(poses, scanning, reach, [lidar.params for lidar in mine])
    range_max = np.repeat(range_max, np.diff(first))
    try:
        # pass 1: the walls and obstacles only (a robot out of every beam's reach can stay)
        scene.hide(within)
        hit, fraction = scene.cast(starts, ends)
        flagged = _flag(pairs, radii, fraction * range_max, mine, first)
        # pass 2: the flagged beams, with the robots they may meet in place
        for recast in _group(scanning, flagged):
            scene.show(recast.needs)
            scene.hide(recast.owners)
            index = np.concatenate(recast.rays)
            hit[index], fraction[index] = scene.cast(starts[index], ends[index])
    finally:
        scene.show(list(scene.hidden))
    return [(hit[a:b], fraction[a:b]) for a, b in itertools.pairwise(first.tolist())]


def _reach(
    poses: Sequence[Pose],
    scanning: Sequence[int],
    reach: FloatArray,
    params: Sequence[LidarModel],
) -> tuple[list[int], _Pairs]:
    """The robots within ``reach`` (per scanning robot) of a scanning robot (the scanning
    robots too), and the pairs of a scanning robot and another robot within its reach."""
    xy = np.array([(x, y) for x, y, _ in poses])
    offsets = xy[None, :, :] - xy[np.asarray(scanning)][:, None, :]
    dist = np.hypot(offsets[..., 0], offsets[..., 1])
    near = dist <= reach[:, None]
    within = np.flatnonzero(near.any(axis=0)).tolist()
    near[np.arange(len(scanning)), np.asarray(scanning)] = False  # not its own body
    k, j = np.nonzero(near)
    yaw = np.array([poses[i][2] for i in scanning])[k]
    angle_min = np.array([lidar.angle_min_rad for lidar in params])[k]
    bearing = np.arctan2(offsets[k, j, 1], offsets[k, j, 0]) - yaw - angle_min
    return within, _Pairs(k, j, dist[k, j], bearing)


def _flag(
    pairs: _Pairs,
    radii: FloatArray,
    static: FloatArray,
    lidars: Sequence[Lidar],
    first: IntArray,
) -> dict[int, tuple[IntArray, set[int]]]:
    """Per scanning robot (position in ``scanning``): its beams (indices into the batch, its
    own starting at ``first[k]``) that may meet a disc of ``radii[j]`` round another robot j
    before their static hit (``static``, m), and the robots they may meet.

    A beam from the centre meets a disc whose centre lies D away only if its bearing is
    within asin(radius / D) of the disc's; of those, the beams whose line passes within
    the radius of the centre and enters the disc before the static hit."""
    if len(pairs.k) == 0:
        return {}  # alone within reach: nothing to cast again
    beams = np.array([lidar.params.beams for lidar in lidars])
    increments = np.array([lidar.params.angle_increment for lidar in lidars])
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
    wide = np.arcsin(np.minimum(1.0, radius / dist)) / inc
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
    ray = first[k[which]] + beam % n[which]
    # the beam's line passes ``across`` from the disc's centre, and enters it ``entry`` along
    off = beam * inc[which] - bearing[which]
    d, r = dist[which], radius[which]
    across = d * np.abs(np.sin(off))
    entry = d * np.cos(off) - np.sqrt(np.maximum(0.0, r * r - across * across))
    maybe = (across <= r) & (entry <= static[ray] + GRAZE_M)
    owner = k[which]
    other = pairs.j[src[which]]
    out: dict[int, tuple[IntArray, set[int]]] = {}
    for kk in np.unique(owner[maybe]).tolist():
        mine = maybe & (owner == kk)
        out[kk] = (np.unique(ray[mine]), set(other[mine].tolist()))
    return out


def _group(scanning: Sequence[int], flagged: dict[int, tuple[IntArray, set[int]]]) -> list[_Recast]:
    """Calls for the flagged beams: a scanner joins the first call in which it need not stand
    for anyone and no owner needs to stand for it."""
    calls: list[_Recast] = []
    for k in sorted(flagged):
        rays, needs = flagged[k]
        own = scanning[k]
        for call in calls:
            if own not in call.needs and not needs & call.owners:
                break
        else:
            call = _Recast()
            calls.append(call)
        call.owners.add(own)
        call.needs |= needs
        call.rays.append(rays)
    return calls

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

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from services.sim.lidar import FloatArray, Lidar, LidarParams
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
    scene: Scene, lidar: Lidar, poses: Sequence[Pose], scanning: Sequence[int]
) -> list[Cast]:
    """(hit, fraction) per beam of each robot in ``scanning`` (indices into ``poses``, where
    the scene has every robot), in that order, as ``scene.cast_from`` gives each."""
    if not scanning:
        return []
    n = lidar.params.beams
    rays = [lidar.rays(*poses[i]) for i in scanning]
    starts, ends = rays[0]
    if len(rays) > 1:
        starts = np.concatenate([s for s, _ in rays])
        ends = np.concatenate([e for _, e in rays])
    radius = scene.params.footprint_radius_m + GRAZE_M
    within, pairs = _reach(poses, scanning, lidar.params.range_max + radius, lidar.params)
    try:
        # pass 1: the walls and obstacles only (a robot out of every beam's reach can stay)
        scene.hide(within)
        hit, fraction = scene.cast(starts, ends)
        flagged = _flag(pairs, radius, fraction * lidar.params.range_max, lidar.params)
        # pass 2: the flagged beams, with the robots they may meet in place
        for recast in _group(scanning, flagged):
            scene.show(recast.needs)
            scene.hide(recast.owners)
            index = np.concatenate(recast.rays)
            hit[index], fraction[index] = scene.cast(starts[index], ends[index])
    finally:
        scene.show(list(scene.hidden))
    return [(hit[k * n : (k + 1) * n], fraction[k * n : (k + 1) * n]) for k in range(len(scanning))]


def _reach(
    poses: Sequence[Pose], scanning: Sequence[int], reach: float, params: LidarParams
) -> tuple[list[int], _Pairs]:
    """The robots within ``reach`` of a scanning robot (the scanning robots too), and the
    pairs of a scanning robot and another robot within ``reach`` of it."""
    xy = np.array([(x, y) for x, y, _ in poses])
    offsets = xy[None, :, :] - xy[np.asarray(scanning)][:, None, :]
    dist = np.hypot(offsets[..., 0], offsets[..., 1])
    near = dist <= reach
    within = np.flatnonzero(near.any(axis=0)).tolist()
    near[np.arange(len(scanning)), np.asarray(scanning)] = False  # not its own body
    k, j = np.nonzero(near)
    yaw = np.array([poses[i][2] for i in scanning])[k]
    bearing = np.arctan2(offsets[k, j, 1], offsets[k, j, 0]) - yaw - params.angle_min
    return within, _Pairs(k, j, dist[k, j], bearing)


def _flag(
    pairs: _Pairs, radius: float, static: FloatArray, params: LidarParams
) -> dict[int, tuple[IntArray, set[int]]]:
    """Per scanning robot (position in ``scanning``): its beams (indices into the batch) that
    may meet a disc of ``radius`` round another robot before their static hit (``static``,
    m), and the robots they may meet.

    A beam from the centre meets a disc whose centre lies D away only if its bearing is
    within asin(radius / D) of the disc's; of those, the beams whose line passes within
    ``radius`` of the centre and enters the disc before the static hit."""
    if len(pairs.k) == 0:
        return {}  # alone within reach: nothing to cast again
    n, inc = params.beams, params.angle_increment
    # a disc round the beams' origin (robots never overlap so far) would meet them all
    wide = np.arcsin(np.minimum(1.0, radius / pairs.dist)) / inc
    half = np.where(pairs.dist > radius, wide, n) + SLACK_BEAMS
    centre = pairs.bearing / inc  # in beams
    lo = np.ceil(centre - half).astype(np.intp)
    count = np.minimum(np.floor(centre + half).astype(np.intp) - lo + 1, n)
    # every (pair, beam) within the pairs' angular extents, flattened
    which = np.repeat(np.arange(len(count)), count)
    beam = lo[which] + np.arange(len(which)) - np.repeat(np.cumsum(count) - count, count)
    ray = pairs.k[which] * n + beam % n
    # the beam's line passes ``across`` from the disc's centre, and enters it ``entry`` along
    off = beam * inc - pairs.bearing[which]
    dist = pairs.dist[which]
    across = dist * np.abs(np.sin(off))
    entry = dist * np.cos(off) - np.sqrt(np.maximum(0.0, radius * radius - across * across))
    maybe = (across <= radius) & (entry <= static[ray] + GRAZE_M)
    owner = pairs.k[which]
    out: dict[int, tuple[IntArray, set[int]]] = {}
    for k in np.unique(owner[maybe]).tolist():
        mine = maybe & (owner == k)
        out[k] = (np.unique(ray[mine]), set(pairs.j[which[mine]].tolist()))
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

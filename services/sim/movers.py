"""A world's moving obstacles in the running sim: bodies in the scene for the contact test,
and shapes in the lidar's beams.

Each physics step the sim puts every mover where its path says it is at the new sim time
(:meth:`Movers.place`), before the robots move: a robot's contact test then meets the mover
where it stands, and a collision names it. The lidar is cast in closed form
(services/sim/fleetcast.py); the movers are cast here, against the same beams, and each beam
keeps the nearer of the two meetings (:meth:`Movers.cast`). The map the planner gets never
holds a mover.

Everything depends on sim time alone (whole steps times the step), so a run repeats exactly,
lockstep or not.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pybullet as p

from services.sim.fleetcast import Cast
from services.sim.lidar import FloatArray, Lidar
from services.sim.mover import MoverSpec
from services.sim.physics import Scene


class Movers:
    """The movers of a world, as bodies of ``scene`` (named after the movers)."""

    def __init__(self, specs: Sequence[MoverSpec], scene: Scene) -> None:
        self.specs = tuple(specs)
        self.client = scene.client
        self.bodies: list[int] = []
        for spec in self.specs:
            sx, sy, sz = spec.size
            if spec.shape == "cylinder":
                shape = p.createCollisionShape(
                    p.GEOM_CYLINDER, radius=sx / 2.0, height=sz, physicsClientId=self.client
                )
                look = {"shapeType": p.GEOM_CYLINDER, "radius": sx / 2.0, "length": sz}
            else:
                half = [sx / 2.0, sy / 2.0, sz / 2.0]
                shape = p.createCollisionShape(
                    p.GEOM_BOX, halfExtents=half, physicsClientId=self.client
                )
                look = {"shapeType": p.GEOM_BOX, "halfExtents": half}
            visual = -1
            if scene.gui:
                visual = p.createVisualShape(
                    rgbaColor=[0.9, 0.5, 0.1, 1.0], physicsClientId=self.client, **look
                )
            body = p.createMultiBody(
                baseMass=0.0,
                baseCollisionShapeIndex=shape,
                baseVisualShapeIndex=visual,
                physicsClientId=self.client,
            )
            scene.names[body] = spec.name
            self.bodies.append(body)
        self.poses: list[tuple[float, float, float]] = []
        self.place(0.0)
        # the fastest mover's speed, m/s (0 without movers)
        self.top_speed_mps = max((s.speed_mps for s in self.specs), default=0.0)
        # how far a box's corner jumps when it turns at a vertex of its path (its heading
        # changes in one step): the contact test must allow for it
        self.turn_jump_m = max(
            (
                s.radius_m - min(s.size[0], s.size[1]) / 2.0
                for s in self.specs
                if s.shape == "box" and len(s.segments) > 1
            ),
            default=0.0,
        )

    def __bool__(self) -> bool:
        return bool(self.specs)

    def place(self, t: float) -> None:
        """Put every mover where it is at sim time ``t``."""
        self.poses = [spec.pose_at(t) for spec in self.specs]
        for body, spec, (x, y, heading) in zip(self.bodies, self.specs, self.poses, strict=True):
            p.resetBasePositionAndOrientation(
                body,
                [x, y, spec.size[2] / 2.0],
                [0.0, 0.0, math.sin(heading / 2.0), math.cos(heading / 2.0)],
                physicsClientId=self.client,
            )

    def cast(self, cast: Cast, pose: tuple[float, float, float], lidar: Lidar) -> Cast:
        """``cast`` (one robot's beams from ``pose``, the static world and the robots) with
        the movers where :meth:`place` last put them: each beam's nearer meeting."""
        hit, fraction = cast
        x, y, yaw = pose
        params = lidar.params
        reach = params.range_max_m
        c, s = math.cos(yaw), math.sin(yaw)
        # every beam as a vector from the robot's centre to its range's end
        dx = (lidar.cos * c - lidar.sin * s) * reach
        dy = (lidar.sin * c + lidar.cos * s) * reach
        nearest = np.full(len(dx), np.inf)
        for spec, (mx, my, heading) in zip(self.specs, self.poses, strict=True):
            if spec.size[2] < lidar.height or math.hypot(mx - x, my - y) > reach + spec.radius_m:
                continue  # below the beams, or beyond them
            if spec.shape == "cylinder":
                met = _disc(x - mx, y - my, dx, dy, spec.size[0] / 2.0)
            else:
                met = _box(x - mx, y - my, dx, dy, heading, spec.size[0], spec.size[1])
            np.minimum(nearest, met, out=nearest)
        seen = nearest <= 1.0
        if not seen.any():
            return cast
        return hit | seen, np.where(seen, np.minimum(fraction, nearest), fraction)


def _disc(ox: float, oy: float, dx: FloatArray, dy: FloatArray, r: float) -> FloatArray:
    """Where along each ray (o + t d, t a fraction of the ray) it enters a disc of radius r
    at the origin; inf where it does not. A ray that starts inside meets it at once."""
    inside = ox * ox + oy * oy - r * r
    if inside <= 0.0:
        return np.zeros(len(dx))
    a = dx * dx + dy * dy
    b = ox * dx + oy * dy  # half the linear term
    disc = b * b - a * inside
    t = (-b - np.sqrt(np.maximum(disc, 0.0))) / a
    out: FloatArray = np.where((disc >= 0.0) & (t >= 0.0), t, np.inf)
    return out


def _box(
    ox: float, oy: float, dx: FloatArray, dy: FloatArray, heading: float, sx: float, sy: float
) -> FloatArray:
    """Where along each ray it enters a box of full extents (sx, sy) at the origin, turned by
    ``heading``; inf where it does not (the slab test, in the box's frame)."""
    c, s = math.cos(-heading), math.sin(-heading)
    lx, ly = c * ox - s * oy, s * ox + c * oy
    ux, uy = c * dx - s * dy, s * dx + c * dy
    hx, hy = sx / 2.0, sy / 2.0
    if abs(lx) <= hx and abs(ly) <= hy:
        return np.zeros(len(dx))
    with np.errstate(divide="ignore", invalid="ignore"):
        tx1, tx2 = (-hx - lx) / ux, (hx - lx) / ux
        ty1, ty2 = (-hy - ly) / uy, (hy - ly) / uy
    # fmin/fmax skip the NaN of a ray along a slab's very edge
    near = np.fmax(np.fmin(tx1, tx2), np.fmin(ty1, ty2))
    far = np.fmin(np.fmax(tx1, tx2), np.fmax(ty1, ty2))
    out: FloatArray = np.where((near <= far) & (near >= 0.0), near, np.inf)
    return out

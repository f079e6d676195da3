"""The pybullet scene: static walls and obstacles, kinematic robot bodies, and the geometry
queries the sim needs (batch ray casts, penetration and contact tests).

Robots are moved kinematically (``resetBasePositionAndOrientation``), so the scene never
calls ``stepSimulation``: pybullet is the collision engine, not the integrator. That keeps
a run exactly reproducible and cheap enough for many times real time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pybullet as p

from services.sim.world import World

# pybullet caps one rayTestBatch call; stay well under the cap of every version
RAY_BATCH = 8192
# distance under which two bodies count as touching, m
CONTACT_TOLERANCE_M = 0.001
# bisection rounds to find how far a blocked move can go: the robot stops within
# step / 2**rounds of the obstacle (under 0.03 mm for a 0.9 mm step)
BISECTION_ROUNDS = 5


@dataclass
class MoveResult:
    x: float
    y: float
    yaw: float
    fraction: float  # of the translation achieved: 1.0 free, 0.0 fully blocked
    touching: frozenset[str]


class Scene:
    """One pybullet client holding a world; robot i is body ``robot_bodies[i]``."""

    def __init__(self, world: World, *, gui: bool = False) -> None:
        self.client = p.connect(p.GUI if gui else p.DIRECT)
        if self.client < 0:
            raise RuntimeError("pybullet could not connect (is a display available for --gui?)")
        self.gui = gui
        self.names: dict[int, str] = {}
        self.params = world.params
        self._ground: set[int] = set()
        if gui:
            p.configureDebugVisualizer(p.COV_ENABLE_GUI, 0, physicsClientId=self.client)
        self._build_static(world)
        self.robot_bodies: list[int] = []
        radius, height = self.params.footprint_radius_m, self.params.height_m
        shape = p.createCollisionShape(
            p.GEOM_CYLINDER, radius=radius, height=height, physicsClientId=self.client
        )
        visual = self._visual(p.GEOM_CYLINDER, radius=radius, length=height, rgba=(0.1, 0.3, 0.9))
        for spec in world.robots:
            body = p.createMultiBody(
                baseMass=0.0,
                baseCollisionShapeIndex=shape,
                baseVisualShapeIndex=visual,
                basePosition=[spec.x, spec.y, height / 2.0],
                baseOrientation=p.getQuaternionFromEuler([0, 0, spec.yaw]),
                physicsClientId=self.client,
            )
            self.names[body] = spec.robot_id
            self.robot_bodies.append(body)

    # -- building --------------------------------------------------------------------------
    def _visual(self, geom: int, *, rgba: tuple[float, float, float], **kwargs: object) -> int:
        # visuals only matter in the GUI; DIRECT mode skips them to build faster
        if not self.gui:
            return -1
        visual: int = p.createVisualShape(
            geom, rgbaColor=[*rgba, 1.0], physicsClientId=self.client, **kwargs
        )
        return visual

    def _box(
        self, name: str, x: float, y: float, yaw: float, half: tuple[float, float, float]
    ) -> int:
        cid = self.client
        shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=list(half), physicsClientId=cid)
        visual = self._visual(p.GEOM_BOX, halfExtents=list(half), rgba=(0.5, 0.5, 0.5))
        body: int = p.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=shape,
            baseVisualShapeIndex=visual,
            basePosition=[x, y, half[2]],
            baseOrientation=p.getQuaternionFromEuler([0, 0, yaw]),
            physicsClientId=cid,
        )
        self.names[body] = name
        return body

    def _build_static(self, world: World) -> None:
        grid = world.grid
        res = grid.resolution
        for col0, row0, col1, row1 in grid.occupied_rectangles():
            cx, cy = grid.cell_to_world((col0 + col1) / 2.0, (row0 + row1) / 2.0)
            half = ((col1 - col0) * res / 2.0, (row1 - row0) * res / 2.0, world.wall_height_m / 2)
            self._box("wall", cx, cy, grid.origin[2], half)
        for ob in world.obstacles:
            sx, sy, sz = ob.size
            if ob.shape == "box":
                self._box(ob.name, ob.x, ob.y, ob.yaw, (sx / 2.0, sy / 2.0, sz / 2.0))
                continue
            shape = p.createCollisionShape(
                p.GEOM_CYLINDER, radius=sx / 2.0, height=sz, physicsClientId=self.client
            )
            visual = self._visual(p.GEOM_CYLINDER, radius=sx / 2.0, length=sz, rgba=(0.6, 0.4, 0.2))
            body = p.createMultiBody(
                baseMass=0.0,
                baseCollisionShapeIndex=shape,
                baseVisualShapeIndex=visual,
                basePosition=[ob.x, ob.y, sz / 2.0],
                physicsClientId=self.client,
            )
            self.names[body] = ob.name
        if self.gui:
            # a floor to look at; it has no collision shape, so nothing ever touches it
            w, h = grid.width * res, grid.height * res
            cx, cy = grid.cell_to_world(grid.width / 2.0, grid.height / 2.0)
            floor = p.createMultiBody(
                baseMass=0.0,
                baseCollisionShapeIndex=-1,
                baseVisualShapeIndex=self._visual(
                    p.GEOM_BOX, halfExtents=[w / 2, h / 2, 0.001], rgba=(0.9, 0.9, 0.85)
                ),
                basePosition=[cx, cy, -0.001],
                physicsClientId=self.client,
            )
            self._ground.add(floor)
            for st in world.stations:
                p.createMultiBody(
                    baseMass=0.0,
                    baseCollisionShapeIndex=-1,
                    baseVisualShapeIndex=self._visual(
                        p.GEOM_CYLINDER, radius=st.radius_m, length=0.002, rgba=(0.2, 0.8, 0.2)
                    ),
                    basePosition=[st.x, st.y, 0.001],
                    physicsClientId=self.client,
                )

    # -- queries ---------------------------------------------------------------------------
    def _place(self, body: int, x: float, y: float, yaw: float) -> None:
        p.resetBasePositionAndOrientation(
            body,
            [x, y, self.params.height_m / 2.0],
            [0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)],
            physicsClientId=self.client,
        )

    def _distances(self, body: int, x: float, y: float) -> dict[int, float]:
        """Smallest signed distance (negative: penetration) to every body near ``body``."""
        cid = self.client
        reach = self.params.footprint_radius_m + 0.01
        near = p.getOverlappingObjects(
            [x - reach, y - reach, -1.0], [x + reach, y + reach, 2.0], physicsClientId=cid
        )
        out: dict[int, float] = {}
        for other, _link in near or ():
            if other == body or other in self._ground or other in out:
                continue
            points = p.getClosestPoints(body, other, CONTACT_TOLERANCE_M, physicsClientId=cid)
            if points:
                out[other] = min(pt[8] for pt in points)
        return out

    def move(
        self, index: int, old: tuple[float, float, float], new: tuple[float, float, float]
    ) -> MoveResult:
        """Move robot ``index`` from ``old`` to ``new`` unless that would penetrate something;
        if it would, go as far along the step as is free (the body is a cylinder, so turning
        in place is always free) and report what it touches."""
        body = self.robot_bodies[index]
        nx, ny, nyaw = new
        self._place(body, nx, ny, nyaw)
        dist = self._distances(body, nx, ny)
        if all(d >= 0.0 for d in dist.values()):
            touching = frozenset(self.names[b] for b, d in dist.items() if d < CONTACT_TOLERANCE_M)
            return MoveResult(nx, ny, nyaw, 1.0, touching)
        blockers = {b for b, d in dist.items() if d < 0.0}
        ox, oy, _ = old
        lo, hi = 0.0, 1.0  # lo is known free (the old position was accepted)
        for _ in range(BISECTION_ROUNDS):
            mid = (lo + hi) / 2.0
            mx, my = ox + (nx - ox) * mid, oy + (ny - oy) * mid
            self._place(body, mx, my, nyaw)
            if any(d < 0.0 for d in self._distances(body, mx, my).values()):
                hi = mid
            else:
                lo = mid
        fx, fy = ox + (nx - ox) * lo, oy + (ny - oy) * lo
        self._place(body, fx, fy, nyaw)
        dist = self._distances(body, fx, fy)
        near = {self.names[b] for b, d in dist.items() if d < CONTACT_TOLERANCE_M}
        return MoveResult(fx, fy, nyaw, lo, frozenset(near | {self.names[b] for b in blockers}))

    def touching(self, index: int, x: float, y: float) -> frozenset[str]:
        """What robot ``index`` touches where it stands (for a robot that did not move)."""
        dist = self._distances(self.robot_bodies[index], x, y)
        return frozenset(self.names[b] for b, d in dist.items() if d < CONTACT_TOLERANCE_M)

    def anything_within(self, index: int, x: float, y: float, radius: float) -> bool:
        """Whether any body comes within ``radius`` of robot ``index``'s centre (x, y)."""
        body = self.robot_bodies[index]
        cid = self.client
        gap = radius - self.params.footprint_radius_m
        near = p.getOverlappingObjects(
            [x - radius, y - radius, -1.0], [x + radius, y + radius, 2.0], physicsClientId=cid
        )
        for other, _link in near or ():
            if other == body or other in self._ground:
                continue
            if p.getClosestPoints(body, other, gap, physicsClientId=cid):
                return True
        return False

    def cast(
        self, starts: npt.NDArray[np.float64], ends: npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.float64]]:
        """Batch ray cast: per ray, whether it hit and the hit fraction along it (a few
        thousand rays per pybullet call)."""
        hit = np.zeros(len(starts), dtype=bool)
        fraction = np.ones(len(starts))
        for lo in range(0, len(starts), RAY_BATCH):
            results = p.rayTestBatch(
                starts[lo : lo + RAY_BATCH],
                ends[lo : lo + RAY_BATCH],
                numThreads=1,  # the sim is one of many processes on a small machine
                physicsClientId=self.client,
            )
            for j, r in enumerate(results):
                if r[0] >= 0:
                    hit[lo + j] = True
                    fraction[lo + j] = r[2]
        return hit, fraction

    def close(self) -> None:
        try:
            p.disconnect(physicsClientId=self.client)
        except p.error:
            pass  # already disconnected (the GUI window was closed)

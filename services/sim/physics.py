"""The pybullet scene: static walls and obstacles, kinematic robot bodies, and the geometry
queries the sim needs (penetration and contact tests; the lidar is cast without Bullet, in
services/sim/fleetcast.py).

Robots are moved kinematically (``resetBasePositionAndOrientation``), so the scene never
calls ``stepSimulation``: pybullet is the collision engine, not the integrator. That keeps
a run exactly reproducible and cheap enough for many times real time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import pybullet as p

from common.footprint import Footprint
from services.sim.world_spec import World

# distance under which two bodies count as touching, m
CONTACT_TOLERANCE_M = 0.001
# how far around a robot the contact test looks; the clearance it finds lets the sim skip
# the test for the steps in which nothing can have come that close (see Simulation._advance)
CLEARANCE_REACH_M = 0.3
# bisection rounds to find how far a blocked move can go: the robot stops within
# step / 2**rounds of the obstacle (under 0.03 mm for a 0.9 mm step)
BISECTION_ROUNDS = 5
# the collision margin of a polygon robot's convex hull, m (see Scene.__init__)
HULL_MARGIN_M = 1e-5


# the 12 outward-facing triangles of a prism whose vertices are the 4 bottom corners
# (counter-clockwise) then the 4 top ones
_PRISM_FACES = (
    *(0, 2, 1, 0, 3, 2),  # bottom, facing down
    *(4, 5, 6, 4, 6, 7),  # top, facing up
    *(0, 1, 5, 0, 5, 4),
    *(1, 2, 6, 1, 6, 5),
    *(2, 3, 7, 2, 7, 6),
    *(3, 0, 4, 3, 4, 7),
)


@dataclass
class MoveResult:
    x: float
    y: float
    yaw: float
    fraction: float  # of the translation achieved: 1.0 free, 0.0 fully blocked
    touching: frozenset[str]
    clearance: float  # distance to the nearest body, m (CLEARANCE_REACH_M if none closer)


class Scene:
    """One pybullet client holding a world; robot i is body ``robot_bodies[i]``."""

    def __init__(self, world: World, *, gui: bool = False) -> None:
        self.client = p.connect(p.GUI if gui else p.DIRECT)
        if self.client < 0:
            raise RuntimeError("pybullet could not connect (is a display available for --gui?)")
        self.gui = gui
        self.names: dict[int, str] = {}
        self._ground: set[int] = set()
        if gui:
            p.configureDebugVisualizer(p.COV_ENABLE_GUI, 0, physicsClientId=self.client)
        self._build_static(world)
        self.robot_bodies: list[int] = []
        # per body: how far its footprint reaches from its centre (the circumscribed radius),
        # its height, and whether turning in place can touch anything (a polygon's corners
        # sweep; a disc's outline does not move)
        self.radius: dict[int, float] = {}
        self.height: dict[int, float] = {}
        self.turns_free: dict[int, bool] = {}
        shapes: dict[tuple[Footprint, float], tuple[int, int]] = {}
        for spec in world.robots:
            footprint, height = spec.model.footprint, spec.model.height_m
            if (footprint, height) not in shapes:
                shapes[(footprint, height)] = self._body_shape(footprint, height)
            shape, visual = shapes[(footprint, height)]
            body = p.createMultiBody(
                baseMass=0.0,
                baseCollisionShapeIndex=shape,
                baseVisualShapeIndex=visual,
                basePosition=[spec.x, spec.y, height / 2.0],
                baseOrientation=p.getQuaternionFromEuler([0, 0, spec.yaw]),
                physicsClientId=self.client,
            )
            if not footprint.is_disc:
                # a convex hull gets a 4 cm margin by default, the body that much rounder; none
                # at all and Bullet's ray test misses it: a hundredth of a millimetre
                p.changeDynamics(
                    body, -1, collisionMargin=HULL_MARGIN_M, physicsClientId=self.client
                )
            self.names[body] = spec.robot_id
            self.robot_bodies.append(body)
            self.radius[body], self.height[body] = footprint.circumscribed_m, height
            self.turns_free[body] = footprint.is_disc
            # placed once more as every later move places it, so a body's transform is always
            # the one _place gives for its pose
            self._place(body, spec.x, spec.y, spec.yaw)

    # -- building --------------------------------------------------------------------------
    def _body_shape(self, footprint: Footprint, height: float) -> tuple[int, int]:
        """A robot body's collision and visual shapes: the upright cylinder of a disc, or the
        prism of a polygon (its convex hull: Bullet's convex shapes are what its contact
        test is exact for; a concave outline is filled in)."""
        if footprint.is_disc:
            return self._cylinder(footprint.radius_m, height)
        half = height / 2.0
        vertices = [[x, y, z] for z in (-half, half) for x, y in footprint.vertices.tolist()]
        shape: int = p.createCollisionShape(
            p.GEOM_MESH, vertices=vertices, physicsClientId=self.client
        )
        visual = -1
        if self.gui:
            visual = p.createVisualShape(
                p.GEOM_MESH,
                vertices=vertices,
                rgbaColor=[0.1, 0.3, 0.9, 1.0],
                physicsClientId=self.client,
            )
        return shape, visual

    def _cylinder(self, radius: float, height: float) -> tuple[int, int]:
        """A robot body's collision and visual shapes."""
        shape: int = p.createCollisionShape(
            p.GEOM_CYLINDER, radius=radius, height=height, physicsClientId=self.client
        )
        visual = self._visual(p.GEOM_CYLINDER, radius=radius, length=height, rgba=(0.1, 0.3, 0.9))
        return shape, visual

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

    def _walls(self, world: World) -> None:
        """The map's occupied cells as one static triangle mesh named "wall": a prism per
        rectangle of cells (a handful of bodies instead of thousands)."""
        grid = world.grid
        vertices: list[list[float]] = []
        indices: list[int] = []
        for col0, row0, col1, row1 in grid.occupied_rectangles():
            corners = [
                grid.cell_to_world(col0, row0),
                grid.cell_to_world(col1, row0),
                grid.cell_to_world(col1, row1),
                grid.cell_to_world(col0, row1),
            ]
            base = len(vertices)
            vertices += [[x, y, 0.0] for x, y in corners]
            vertices += [[x, y, world.wall_height_m] for x, y in corners]
            indices += [base + k for k in _PRISM_FACES]
        if not vertices:
            return
        cid = self.client
        shape = p.createCollisionShape(
            p.GEOM_MESH, vertices=vertices, indices=indices, physicsClientId=cid
        )
        visual = -1
        if self.gui:
            visual = p.createVisualShape(
                p.GEOM_MESH,
                vertices=vertices,
                indices=indices,
                rgbaColor=[0.5, 0.5, 0.5, 1.0],
                physicsClientId=cid,
            )
        body = p.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=shape,
            baseVisualShapeIndex=visual,
            physicsClientId=cid,
        )
        # a mesh gets a 1 mm margin by default: robots would stop 1 mm short of the walls
        p.changeDynamics(body, -1, collisionMargin=0.0, physicsClientId=cid)
        self.names[body] = "wall"

    def _build_static(self, world: World) -> None:
        grid = world.grid
        res = grid.resolution
        self._walls(world)
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
            # look at the whole map from above and a little to the south
            p.resetDebugVisualizerCamera(
                cameraDistance=0.9 * max(w, h),
                cameraYaw=0.0,
                cameraPitch=-60.0,
                cameraTargetPosition=[cx, cy, 0.0],
                physicsClientId=self.client,
            )
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
            [x, y, self.height[body] / 2.0],
            [0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)],
            physicsClientId=self.client,
        )

    def _distances(self, body: int, x: float, y: float, reach: float) -> dict[int, float]:
        """Smallest signed distance (negative: penetration) to every body within ``reach``
        of ``body`` standing at (x, y)."""
        cid = self.client
        box = self.radius[body] + reach
        near = p.getOverlappingObjects(
            [x - box, y - box, -1.0], [x + box, y + box, 2.0], physicsClientId=cid
        )
        out: dict[int, float] = {}
        for other, _link in near or ():
            if other == body or other in self._ground or other in out:
                continue
            points = p.getClosestPoints(body, other, reach, physicsClientId=cid)
            if points:
                out[other] = min(pt[8] for pt in points)
        return out

    def _touching(self, dist: dict[int, float]) -> frozenset[str]:
        return frozenset(self.names[b] for b, d in dist.items() if d < CONTACT_TOLERANCE_M)

    def place(self, index: int, x: float, y: float, yaw: float) -> None:
        """Put robot ``index`` there unchecked (the caller knows the way is clear)."""
        self._place(self.robot_bodies[index], x, y, yaw)

    def move(
        self, index: int, old: tuple[float, float, float], new: tuple[float, float, float]
    ) -> MoveResult:
        """Move robot ``index`` from ``old`` to ``new`` unless that would penetrate something;
        if it would, go as far along the step as is free and report what it touches. A disc
        turns in place freely; a polygon whose turn would push a corner into something keeps
        its old heading for the step (and then moves as far as is free at that heading)."""
        body = self.robot_bodies[index]
        nx, ny, nyaw = new
        self._place(body, nx, ny, nyaw)
        dist = self._distances(body, nx, ny, CLEARANCE_REACH_M)
        if all(d >= 0.0 for d in dist.values()):
            clearance = min(dist.values(), default=CLEARANCE_REACH_M)
            return MoveResult(nx, ny, nyaw, 1.0, self._touching(dist), clearance)
        blockers = {self.names[b] for b, d in dist.items() if d < 0.0}
        ox, oy, oyaw = old
        if not self.turns_free[body] and nyaw != oyaw:
            self._place(body, ox, oy, nyaw)
            if self._penetrates(body, ox, oy):
                nyaw = oyaw  # the turn itself is blocked
        lo, hi = 0.0, 1.0  # lo is known free (the old position was accepted)
        for _ in range(BISECTION_ROUNDS):
            mid = (lo + hi) / 2.0
            mx, my = ox + (nx - ox) * mid, oy + (ny - oy) * mid
            self._place(body, mx, my, nyaw)
            if self._penetrates(body, mx, my):
                hi = mid
            else:
                lo = mid
        fx, fy = ox + (nx - ox) * lo, oy + (ny - oy) * lo
        self._place(body, fx, fy, nyaw)
        touching = self._touching(self._distances(body, fx, fy, CONTACT_TOLERANCE_M))
        return MoveResult(fx, fy, nyaw, lo, touching | blockers, 0.0)

    def _penetrates(self, body: int, x: float, y: float) -> bool:
        return any(d < 0.0 for d in self._distances(body, x, y, CONTACT_TOLERANCE_M).values())

    def probe(self, index: int, x: float, y: float) -> tuple[frozenset[str], float]:
        """What robot ``index`` touches where it stands, and its clearance (for a robot that
        did not move)."""
        dist = self._distances(self.robot_bodies[index], x, y, CLEARANCE_REACH_M)
        return self._touching(dist), max(0.0, min(dist.values(), default=CLEARANCE_REACH_M))

    def close(self) -> None:
        try:
            p.disconnect(physicsClientId=self.client)
        except p.error:
            pass  # already disconnected (the GUI window was closed)

"""Where the bad goals go on a world: a point outside its map, one inside an obstacle."""

from __future__ import annotations

from pathlib import Path

from common.errors import UsageError


def bad_goals(world: Path) -> dict[str, tuple[float, float]]:
    """``outside``: 10 m beyond the map's far corner; ``obstacle``: the centre of the
    largest block of occupied cells on the map."""
    from services.sim.world_spec import load_world

    grid = load_world(world).grid
    far = grid.cell_to_world(grid.width, grid.height)
    rects = grid.occupied_rectangles()
    if not rects:
        raise UsageError(f"{world.name}: its map has no obstacle to aim a goal into")
    c0, r0, c1, r1 = max(rects, key=lambda r: (r[2] - r[0]) * (r[3] - r[1]))
    inside = grid.cell_to_world((c0 + c1) / 2, (r0 + r1) / 2)
    return {
        "outside": (round(far[0] + 10.0, 2), round(far[1] + 10.0, 2)),
        "obstacle": (round(inside[0], 2), round(inside[1], 2)),
    }

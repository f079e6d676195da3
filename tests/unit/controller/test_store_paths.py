"""The controller's store and the planned_path table: the path in force per robot, from a
notification's image when it has one, from the table otherwise, again after a newer row."""

from __future__ import annotations

from typing import Any

from common.contract import keys
from tests.unit.controller.rig import Rig


def path_row(xs: list[float]) -> dict[str, Any]:
    return {
        "robot_id": "r1",
        "stamp": 10.0,
        "goal_id": 3,
        "target": "goal",
        "target_x": xs[-1] if xs else None,
        "target_y": 0.0 if xs else None,
        "xs": xs,
        "ys": [0.0] * len(xs),
        "length_m": xs[-1] - xs[0] if xs else 0.0,
    }


async def test_the_path_in_force_comes_from_the_image_then_follows_newer_rows() -> None:
    r = Rig(images=True)
    assert await r.store.planned_path("r1") is None  # none yet (read once: nothing)
    first = r.contract.insert(keys.PLANNED_PATH, path_row([0.0, 2.0]))
    path = await r.store.planned_path("r1")
    assert path is not None and (path.id, path.xs, path.goal_id) == (first, (0.0, 2.0), 3)
    reads = r.store.paths.reads
    empty = r.contract.insert(keys.PLANNED_PATH, path_row([]))
    path = await r.store.planned_path("r1")
    assert path is not None and path.id == empty and path.empty
    assert r.store.paths.reads == reads  # both from their images: no query


async def test_without_images_a_notification_makes_the_store_read_the_table() -> None:
    r = Rig(images=False)
    first = r.contract.insert(keys.PLANNED_PATH, path_row([0.0, 1.0]))
    path = await r.store.planned_path("r1")
    assert path is not None and path.id == first
    second = r.contract.insert(keys.PLANNED_PATH, path_row([0.0, 3.0]))
    path = await r.store.planned_path("r1")
    assert path is not None and (path.id, path.xs) == (second, (0.0, 3.0))
    r.store.forget(["r1"])  # the robot changed hands: read afresh
    assert r.store.paths.peek("r1") is None

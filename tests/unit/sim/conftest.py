"""Helpers for the sim's unit tests: small hand-made maps and worlds in a temporary folder."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from services.sim.mapserver import write_pgm

FREE_PX, OCCUPIED_PX, UNKNOWN_PX = 254, 0, 205

MAP_DOC: dict[str, Any] = {
    "resolution": 0.05,
    "origin": [0.0, 0.0, 0.0],
    "occupied_thresh": 0.65,
    "free_thresh": 0.196,
    "negate": 0,
}


def draw(
    width_m: float, height_m: float, walls: Sequence[tuple[float, float, float, float]]
) -> Any:
    """Pixels (row 0 on top, as in a PGM) of a free map with occupied rectangles
    ``(x0, y0, x1, y1)`` in metres, 0.05 m cells, origin at (0, 0)."""
    w, h = round(width_m / 0.05), round(height_m / 0.05)
    bottom_up = np.full((h, w), FREE_PX, dtype=np.uint8)
    for x0, y0, x1, y1 in walls:
        bottom_up[round(y0 / 0.05) : round(y1 / 0.05), round(x0 / 0.05) : round(x1 / 0.05)] = (
            OCCUPIED_PX
        )
    return np.flipud(bottom_up)


def write_map(folder: Path, pixels: Any, name: str = "map", **overrides: Any) -> Path:
    """A map_server YAML + P5 PGM; ``overrides`` replace (or, set to None, drop) YAML keys."""
    write_pgm(folder / f"{name}.pgm", pixels)
    doc = {"image": f"{name}.pgm", **MAP_DOC}
    for key, value in overrides.items():
        if value is None:
            doc.pop(key, None)
        else:
            doc[key] = value
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def write_world(folder: Path, map_file: str, name: str = "world", **doc: Any) -> Path:
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump({"name": name, "map": map_file, **doc}))
    return path


MakeWorld = Callable[..., Path]


@pytest.fixture
def make_world(tmp_path: Path) -> MakeWorld:
    """``make_world(width_m, height_m, walls, robots=[...], ...)`` -> world file path."""

    def make(
        width_m: float,
        height_m: float,
        walls: Sequence[tuple[float, float, float, float]] = (),
        **doc: Any,
    ) -> Path:
        write_map(tmp_path, draw(width_m, height_m, walls))
        doc.setdefault("robots", [{"id": "r1", "x": 1.0, "y": 1.0, "yaw": 0.0}])
        return write_world(tmp_path, "map.yaml", **doc)

    return make

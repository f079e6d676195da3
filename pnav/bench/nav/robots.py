"""The robot a benchmark world is made for, or run with: its name, top speed and footprint.

Generating a world needs the footprint (the path check); scoring a run needs the top speed
(BARN's optimal time); both come from the project's robot models
(``common.robotmodel.load_model``, ``models/*.yaml``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import yaml

from common import yamldoc
from common.errors import UsageError
from common.footprint import Footprint, Polygon

if TYPE_CHECKING:
    from pnav.bench.nav.worldfile import BenchmarkWorld


@dataclass(frozen=True)
class RobotFit:
    """What the benchmark needs of a robot model."""

    name: str
    max_linear_mps: float
    footprint_radius_m: float
    # what a world file's robot entry names for the sim to load it: a shipped model's name,
    # or a model file's absolute path ("": the name)
    ref: str = ""
    # the model's footprint polygon (common/footprint.py); None: the disc of the radius
    footprint_polygon: Polygon | None = None

    @property
    def footprint(self) -> Footprint:
        return Footprint.of(self.footprint_radius_m, self.footprint_polygon)

    @property
    def world_ref(self) -> str:
        return self.ref or self.name

    def __post_init__(self) -> None:
        if self.max_linear_mps <= 0 or self.footprint_radius_m <= 0:
            raise UsageError(
                f"robot {self.name}: top speed and footprint radius must be positive, got "
                f"{self.max_linear_mps} m/s and {self.footprint_radius_m} m"
            )


def resolve_model(name: str) -> RobotFit:
    """The robot model ``name`` (a name from ``models/`` or a model file's path); a
    ModelError (a UsageError) naming the known models when there is none."""
    from common.robotmodel import load_model, model_names

    model = load_model(name)
    ref = name if name in model_names() else str(Path(name).resolve())
    return RobotFit(
        model.name, model.max_linear_mps, model.footprint_radius_m, ref, model.footprint_polygon
    )


def for_model(world: BenchmarkWorld, robot: RobotFit, folder: Path) -> BenchmarkWorld:
    """``world`` run and scored with ``robot``: OT at its top speed, the BARN protocol's time
    limit for that speed (the default protocol keeps the world's), and, when the world was
    made for another model (or names none), a copy of its world file under ``folder`` whose
    robot is this model (the map and the obstacles unchanged)."""
    from pnav.bench.nav import barn, dynabarn
    from pnav.bench.nav.scores import optimal_time

    limit = world.time_limit_s
    if world.protocol in (barn.PROTOCOL, dynabarn.PROTOCOL):
        limit = barn.time_limit(robot.max_linear_mps)
    world_file = world.world_file
    if robot.name != world.model:
        doc = yamldoc.load(world.world_file.read_text())
        doc["map"] = str(world.map_file.resolve())  # the copy lives elsewhere
        for entry in doc["robots"]:
            entry["model"] = robot.world_ref
        folder.mkdir(parents=True, exist_ok=True)
        world_file = folder / f"{world.name}__{robot.name}.yaml"
        world_file.write_text(yaml.safe_dump(doc, sort_keys=False, default_flow_style=None))
    return replace(
        world,
        world_file=world_file,
        top_speed_mps=robot.max_linear_mps,
        optimal_time_s=optimal_time(world.reference_length_m, robot.max_linear_mps),
        time_limit_s=limit,
        model=robot.name,
    )


def too_big(worlds: Sequence[BenchmarkWorld], robot: RobotFit) -> list[str]:
    """The worlds whose path was checked for a smaller robot than ``robot``: it may not fit
    through them."""
    return [w.name for w in worlds if robot.footprint_radius_m > w.footprint_radius_m + 1e-9]

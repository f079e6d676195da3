"""The robot a benchmark world is made for, or run with: its name, top speed and footprint.

Generating a world needs the footprint (the path check); scoring a run needs the top speed
(BARN's optimal time); both come from the project's robot models
(``common.robotmodel.load_model``, ``models/*.yaml``). A world run with another robot than
its own is ``pnav.bench.nav.worldfile.for_model``'s.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from common.errors import UsageError
from common.footprint import Footprinted, Polygon


@dataclass(frozen=True)
class RobotFit(Footprinted):
    """What the benchmark needs of a robot model (its ``footprint``: Footprinted)."""

    name: str
    max_linear_mps: float
    footprint_radius_m: float
    # what a world file's robot entry names for the sim to load it: a shipped model's name,
    # or a model file's absolute path ("": the name)
    ref: str = ""
    # the model's footprint polygon (common/footprint.py); None: the disc of the radius
    footprint_polygon: Polygon | None = None

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

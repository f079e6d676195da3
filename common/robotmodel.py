"""Robot models: a robot described once (footprint, limits, lidar) and used everywhere.

A model is a YAML file in ``models/`` (format in docs/SIM.md, "Robot models"): the sim builds
the body and the lidar from it, the bridge writes it into the ``robot`` row
(:meth:`RobotModel.robot_row`, CONTRACT.md), and every scenario reads its limits from that row.

Every field is required in a model file, so a model never silently inherits the Burger's
figures; a world file may override some of them (``overrides``). Every refusal is a
:class:`~common.errors.ModelError` naming the file and the field, e.g.
``models/jackal.yaml: lidar.beams: must be an integer, got 'many'``. Every figure is bounded
to physical values (``ROBOT_BOUNDS``; the lidar's by the robot table's CHECKs) and a refusal
names the bound and why: ``max_linear_mps: must be at most 10 m/s (the fastest velocity a
command may carry, CONTRACT.md), got 1e+308``. A field the format does not know (a typo) is
refused with difflib's closest known name: ``unknown field 'battry_capacity_wh' (did you mean
'battery_capacity_wh'? known: ...)``.

Beam spacing (the one rule, CONTRACT.md ``robot.lidar_fov_rad``): a lidar whose field of view
is a full turn spaces its beams ``fov / beams`` apart (the last beam does not repeat the first);
any other spans its field of view from the first beam to the last, ``fov / (beams - 1)`` apart,
as a ROS ``LaserScan``'s ``angle_min`` .. ``angle_max`` and Gazebo's ray sensor do.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import yaml

from common import yamldoc
from common.contract import limits
from common.errors import ModelError
from common.footprint import Footprinted, Polygon, polygon_problem

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "models"
DEFAULT_MODEL = "turtlebot3_burger"
FULL_TURN = 2.0 * math.pi
# a fov within this of 2 pi is a full turn: YAML figures are written with finite digits
FULL_TURN_TOLERANCE = 1e-6
# how far a stated angle_increment_rad may be from the one beams and fov give (data sheets
# round the angular resolution: 0.375 deg for 720 beams over 270 deg)
INCREMENT_TOLERANCE = 0.005
# the contract's bounds (schema.sql, robot_accel_bounded and robot_lidar_sane)
MAX_ACCEL = 100.0
MAX_BEAMS = 100_000
MAX_RANGE_M = 1000.0
MAX_NOISE_M = 10.0
MAX_RATE_HZ = 1000.0

# Upper bounds of a model's figures: physical values, far above any ground robot's, so that
# a slip (1e308, a value in mm) is refused at load, naming the bound, instead of reaching
# the robot row and every scenario's arithmetic. field -> (bound, unit, why this bound).
ROBOT_BOUNDS: dict[str, tuple[float, str, str]] = {
    "footprint_radius_m": (5.0, "m", "a ground robot 10 m across"),
    "wheel_radius_m": (2.0, "m", "a wheel 4 m high"),
    "wheel_separation_m": (10.0, "m", "a ground robot 10 m across"),
    "max_linear_mps": (
        limits.MAX_ABS_LINEAR_MPS,
        "m/s",
        "the fastest velocity a command may carry, CONTRACT.md",
    ),
    "max_angular_rps": (
        limits.MAX_ABS_ANGULAR_RPS,
        "rad/s",
        "the fastest turn a command may carry, CONTRACT.md",
    ),
    "max_linear_accel_mps2": (MAX_ACCEL, "m/s^2", "the robot table's bound, CONTRACT.md"),
    "max_angular_accel_rps2": (MAX_ACCEL, "rad/s^2", "the robot table's bound, CONTRACT.md"),
    "battery_capacity_wh": (100_000.0, "Wh", "100 kWh, a large industrial vehicle's"),
    "height_m": (10.0, "m", "a ground robot 10 m high"),
}
LIDAR_HEIGHT_BOUND = (10.0, "m", "a lidar 10 m above the floor")


@dataclass(frozen=True)
class LidarModel:
    """A 2-D lidar: beam 0 at ``angle_min_rad`` from the heading, counter-clockwise."""

    beams: int
    angle_min_rad: float
    fov_rad: float
    range_min_m: float
    range_max_m: float
    noise_m: float  # standard deviation of the Gaussian range noise
    rate_hz: float  # sweeps per second
    height_m: float  # of the beams' plane above the floor

    @property
    def full_turn(self) -> bool:
        return abs(self.fov_rad - FULL_TURN) <= FULL_TURN_TOLERANCE

    @property
    def angle_increment(self) -> float:
        """Angle between consecutive beams, rad (the rule in this module's docstring)."""
        if self.full_turn:
            return FULL_TURN / self.beams
        return self.fov_rad / (self.beams - 1) if self.beams > 1 else 0.0

    @property
    def angle_max_rad(self) -> float:
        """Angle of the last beam relative to the heading, rad (ROS LaserScan's angle_max)."""
        return self.angle_min_rad + self.angle_increment * (self.beams - 1)


@dataclass(frozen=True)
class RobotModel(Footprinted):
    """A differential-drive robot; field names end in the contract's units. Its footprint is
    ``footprint_polygon`` when the model gives one (robot frame, counter-clockwise,
    common/footprint.py), else the disc of ``footprint_radius_m``."""

    name: str
    footprint_radius_m: float
    wheel_radius_m: float
    wheel_separation_m: float
    max_linear_mps: float
    max_angular_rps: float
    max_linear_accel_mps2: float
    max_angular_accel_rps2: float
    battery_capacity_wh: float
    height_m: float
    lidar: LidarModel
    footprint_polygon: Polygon | None = None

    def robot_row(self) -> dict[str, object]:
        """The ``robot`` table's model columns (CONTRACT.md), as the world message carries
        them; the bridge writes them as they are."""
        lidar = self.lidar
        return {
            "model": self.name,
            "wheel_radius_m": self.wheel_radius_m,
            "wheel_separation_m": self.wheel_separation_m,
            "max_linear_mps": self.max_linear_mps,
            "max_angular_rps": self.max_angular_rps,
            "footprint_radius_m": self.footprint_radius_m,
            "footprint_polygon": (
                None
                if self.footprint_polygon is None
                else [list(v) for v in self.footprint_polygon]
            ),
            "battery_capacity_wh": self.battery_capacity_wh,
            "max_linear_accel_mps2": self.max_linear_accel_mps2,
            "max_angular_accel_rps2": self.max_angular_accel_rps2,
            "lidar_beams": lidar.beams,
            "lidar_angle_min_rad": lidar.angle_min_rad,
            "lidar_fov_rad": lidar.fov_rad,
            "lidar_range_min_m": lidar.range_min_m,
            "lidar_range_max_m": lidar.range_max_m,
            "lidar_noise_m": lidar.noise_m,
            "lidar_rate_hz": lidar.rate_hz,
        }


ROBOT_FIELDS = tuple(
    f.name for f in fields(RobotModel) if f.name not in ("name", "lidar", "footprint_polygon")
)
# optional in a file: absent, the footprint is the disc of footprint_radius_m
OPTIONAL_FIELDS = ("footprint_polygon",)
LIDAR_FIELDS = tuple(f.name for f in fields(LidarModel))
# optional in a file: a cross-check of beams against the field of view, never stored
LIDAR_CHECK_FIELDS = ("angle_increment_rad",)


def model_names() -> list[str]:
    """The shipped models (``models/*.yaml``), sorted."""
    return sorted(p.stem for p in MODELS.glob("*.yaml"))


def model_path(name_or_path: str | Path) -> Path:
    """The file of a model name (``jackal``) or a path to a model file."""
    given = Path(name_or_path)
    if given.suffix in (".yaml", ".yml") or given.parent != Path("."):
        if given.is_file():
            return given
        raise ModelError(f"{given}: model file not found")
    path = MODELS / f"{given}.yaml"
    if path.is_file():
        return path
    raise ModelError(
        f"no robot model {str(name_or_path)!r}: give a model file, or one of: "
        + ", ".join(model_names())
    )


def _shown(path: Path) -> str:
    """A shipped model as ``models/jackal.yaml``; any other file as given."""
    try:
        return str(path.resolve().relative_to(ROOT))
    except ValueError:
        return str(path)


def load_model(
    name_or_path: str | Path, overrides: Mapping[str, object] | None = None
) -> RobotModel:
    """Load and check a model by name (``models/<name>.yaml``) or file, with ``overrides``
    (same layout as the file, e.g. ``{"max_linear_mps": 1.5, "lidar": {"rate_hz": 10}}``)
    applied on top; ModelError naming the file and the field for anything wrong."""
    path = model_path(name_or_path)
    where = _shown(path)
    try:
        doc = yamldoc.load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ModelError(f"{where}: cannot read model YAML: {exc}") from None
    if not isinstance(doc, dict):
        raise ModelError(f"{where}: a model file must be a YAML mapping, got {doc!r}")
    if overrides:
        doc = _merged(doc, overrides, f"{where} (overridden)")
        where = f"{where} (overridden)"
    return parse_model(doc, where)


def _merged(doc: dict[str, Any], overrides: Mapping[str, object], where: str) -> dict[str, Any]:
    out = dict(doc)
    for key, value in overrides.items():
        if key == "lidar":
            if not isinstance(value, Mapping):
                raise ModelError(f"{where}: lidar: must be a mapping, got {value!r}")
            base = out.get("lidar")
            out["lidar"] = {**(base if isinstance(base, dict) else {}), **value}
        else:
            out[key] = value
    return out


def parse_model(doc: Mapping[str, Any], where: str) -> RobotModel:
    """A model from its YAML document; ``where`` (the file) starts every error message."""
    _no_unknown(doc, where, "", ("name", *ROBOT_FIELDS, *OPTIONAL_FIELDS, "lidar"))
    name = doc.get("name")
    if not isinstance(name, str) or not name or not all(c.isalnum() or c in "_-" for c in name):
        raise ModelError(f"{where}: name: must be a name matching [A-Za-z0-9_-]+, got {name!r}")
    lidar_doc = doc.get("lidar")
    if lidar_doc is None:
        raise ModelError(f"{where}: lidar: missing (the robot's 2-D lidar)")
    if not isinstance(lidar_doc, Mapping):
        raise ModelError(f"{where}: lidar: must be a mapping, got {lidar_doc!r}")
    values = {key: _positive(doc, key, where, "") for key in ROBOT_FIELDS}
    for key, bound in ROBOT_BOUNDS.items():
        _at_most(values[key], bound[0], where, key, bound)
    polygon = _polygon(doc, where)
    return RobotModel(
        name=name, lidar=_lidar(lidar_doc, where), footprint_polygon=polygon, **values
    )


def _polygon(doc: Mapping[str, Any], where: str) -> Polygon | None:
    """The optional footprint polygon, checked as the robot table's CHECKs check it."""
    value = doc.get("footprint_polygon")
    if value is None:
        return None
    problem = polygon_problem(value)
    if problem is not None:
        raise ModelError(f"{where}: footprint_polygon: {problem}")
    return tuple((float(x), float(y)) for x, y in value)


def _lidar(doc: Mapping[str, Any], where: str) -> LidarModel:
    _no_unknown(doc, where, "lidar.", (*LIDAR_FIELDS, *LIDAR_CHECK_FIELDS))
    beams = doc.get("beams")
    if beams is None:
        raise ModelError(f"{where}: lidar.beams: missing")
    if isinstance(beams, bool) or not isinstance(beams, int):
        raise ModelError(f"{where}: lidar.beams: must be an integer, got {beams!r}")
    if not 1 <= beams <= MAX_BEAMS:
        raise ModelError(
            f"{where}: lidar.beams: must be within [1, {MAX_BEAMS}] (the robot table's bound, "
            f"CONTRACT.md), got {beams}"
        )
    angle_min = _number(doc, "angle_min_rad", where, "lidar.")
    if abs(angle_min) > FULL_TURN:
        raise ModelError(f"{where}: lidar.angle_min_rad: must be within +-2 pi, got {angle_min}")
    fov = _positive(doc, "fov_rad", where, "lidar.")
    _at_most(
        fov,
        FULL_TURN + FULL_TURN_TOLERANCE,
        where,
        "lidar.fov_rad",
        (FULL_TURN, "rad", "a full turn"),
    )
    range_min = _number(doc, "range_min_m", where, "lidar.")
    if range_min < 0:
        raise ModelError(f"{where}: lidar.range_min_m: must be >= 0, got {range_min}")
    range_max = _positive(doc, "range_max_m", where, "lidar.")
    if range_max <= range_min:
        raise ModelError(
            f"{where}: lidar.range_max_m: must be greater than range_min_m ({range_min}), "
            f"got {range_max}"
        )
    _at_most(range_max, MAX_RANGE_M, where, "lidar.range_max_m", (MAX_RANGE_M, "m", _TABLE))
    noise = _number(doc, "noise_m", where, "lidar.")
    if noise < 0:
        raise ModelError(f"{where}: lidar.noise_m: must be >= 0, got {noise}")
    _at_most(noise, MAX_NOISE_M, where, "lidar.noise_m", (MAX_NOISE_M, "m", _TABLE))
    rate = _positive(doc, "rate_hz", where, "lidar.")
    _at_most(rate, MAX_RATE_HZ, where, "lidar.rate_hz", (MAX_RATE_HZ, "Hz", _TABLE))
    height = _positive(doc, "height_m", where, "lidar.")
    _at_most(height, LIDAR_HEIGHT_BOUND[0], where, "lidar.height_m", LIDAR_HEIGHT_BOUND)
    lidar = LidarModel(
        beams=beams,
        angle_min_rad=angle_min,
        fov_rad=FULL_TURN if abs(fov - FULL_TURN) <= FULL_TURN_TOLERANCE else fov,
        range_min_m=range_min,
        range_max_m=range_max,
        noise_m=noise,
        rate_hz=rate,
        height_m=height,
    )
    _check_spacing(lidar, doc, where)
    return lidar


def _check_spacing(lidar: LidarModel, doc: Mapping[str, Any], where: str) -> None:
    """Beams that cannot cover the field of view, or that disagree with a stated increment."""
    deg = math.degrees
    if not lidar.full_turn and lidar.beams < 2:
        raise ModelError(
            f"{where}: lidar.beams: one beam cannot span a {deg(lidar.fov_rad):.4g} deg field "
            "of view (at least 2, the first and the last)"
        )
    if "angle_increment_rad" not in doc:
        return
    stated = _positive(doc, "angle_increment_rad", where, "lidar.")
    actual = lidar.angle_increment
    if abs(stated - actual) > INCREMENT_TOLERANCE * actual:
        raise ModelError(
            f"{where}: lidar.beams: {lidar.beams} beams over a {deg(lidar.fov_rad):.4g} deg "
            f"field of view are {deg(actual):.4g} deg apart, but lidar.angle_increment_rad "
            f"says {deg(stated):.4g} deg"
        )


# -- field readers ----------------------------------------------------------------------------
def _no_unknown(doc: Mapping[str, Any], where: str, prefix: str, known: tuple[str, ...]) -> None:
    key = yamldoc.unknown_key(doc, known)
    if key is not None:
        problem = yamldoc.unknown_key_problem(key, known, "field")
        raise ModelError(f"{where}: {prefix}{key}: {problem}")


def _number(doc: Mapping[str, Any], key: str, where: str, prefix: str) -> float:
    if key not in doc:
        raise ModelError(f"{where}: {prefix}{key}: missing")
    value = doc[key]
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ModelError(f"{where}: {prefix}{key}: must be a number, got {value!r}")
    if not math.isfinite(value):
        raise ModelError(f"{where}: {prefix}{key}: must be finite, got {value!r}")
    return float(value)


def _positive(doc: Mapping[str, Any], key: str, where: str, prefix: str) -> float:
    value = _number(doc, key, where, prefix)
    if value <= 0:
        raise ModelError(f"{where}: {prefix}{key}: must be positive, got {value}")
    return value


_TABLE = "the robot table's bound, CONTRACT.md"


def _at_most(
    value: float, limit: float, where: str, field: str, bound: tuple[float, str, str]
) -> None:
    """Refuse ``value`` above ``limit``, naming the bound, its unit and why it is that."""
    if value > limit:
        figure, unit, why = bound
        raise ModelError(
            f"{where}: {field}: must be at most {figure:.6g} {unit} ({why}), got {value:.6g}"
        )

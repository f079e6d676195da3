"""Robot models (common/robotmodel.py): the shipped ones load with the documented figures,
overrides apply, and every bad model is refused at load naming the file and the field."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
import yaml

from common.errors import ModelError, UsageError
from common.robotmodel import MODELS, load_model, model_names


def _burger_doc() -> dict[str, Any]:
    doc = yaml.safe_load((MODELS / "turtlebot3_burger.yaml").read_text())
    assert isinstance(doc, dict)
    return doc


def _write(tmp_path: Path, doc: object, name: str = "bot.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc))
    return path


def _refusal(path: Path) -> str:
    with pytest.raises(ModelError) as info:
        load_model(path)
    return str(info.value)


def test_shipped_models_are_listed() -> None:
    assert {"turtlebot3_burger", "jackal"} <= set(model_names())


def test_burger_model_has_todays_figures() -> None:
    m = load_model("turtlebot3_burger")
    assert (m.footprint_radius_m, m.max_linear_mps, m.max_angular_rps) == (0.105, 0.22, 2.84)
    assert (m.wheel_radius_m, m.wheel_separation_m, m.battery_capacity_wh) == (0.033, 0.16, 19.98)
    assert (m.max_linear_accel_mps2, m.max_angular_accel_rps2) == (2.5, 31.25)
    lidar = m.lidar
    assert (lidar.beams, lidar.range_min_m, lidar.range_max_m, lidar.rate_hz) == (
        360,
        0.12,
        3.5,
        5.0,
    )
    assert lidar.full_turn and lidar.angle_increment == pytest.approx(math.radians(1.0))


def test_jackal_model_has_the_issue_figures() -> None:
    m = load_model("jackal")
    assert (m.footprint_radius_m, m.max_linear_mps, m.max_angular_rps) == (0.22, 2.0, 4.0)
    assert m.max_linear_accel_mps2 > 0 and m.max_angular_accel_rps2 > 0
    lidar = m.lidar
    assert lidar.beams == 720 and lidar.range_max_m == 30.0
    assert math.degrees(lidar.fov_rad) == pytest.approx(270.0, abs=1e-6)
    assert not lidar.full_turn
    # a partial field of view spans first to last beam: fov / (beams - 1)
    assert lidar.angle_increment == pytest.approx(lidar.fov_rad / 719)
    assert lidar.angle_max_rad == pytest.approx(lidar.angle_min_rad + lidar.fov_rad)


def test_robot_row_names_every_model_column_of_the_contract() -> None:
    row = load_model("jackal").robot_row()
    assert row["model"] == "jackal"
    assert row["lidar_beams"] == 720 and row["lidar_range_max_m"] == 30.0
    assert row["max_linear_accel_mps2"] == 10.0
    assert set(row) == {
        "model",
        "wheel_radius_m",
        "wheel_separation_m",
        "max_linear_mps",
        "max_angular_rps",
        "footprint_radius_m",
        "footprint_polygon",
        "battery_capacity_wh",
        "max_linear_accel_mps2",
        "max_angular_accel_rps2",
        "lidar_beams",
        "lidar_angle_min_rad",
        "lidar_fov_rad",
        "lidar_range_min_m",
        "lidar_range_max_m",
        "lidar_noise_m",
        "lidar_rate_hz",
    }


def test_overrides_replace_only_the_fields_named() -> None:
    m = load_model("jackal", {"max_linear_mps": 1.5, "lidar": {"rate_hz": 10}})
    base = load_model("jackal")
    assert m.max_linear_mps == 1.5 and m.lidar.rate_hz == 10.0
    assert m.max_angular_rps == base.max_angular_rps and m.lidar.beams == base.lidar.beams


def test_a_model_file_given_by_path_loads(tmp_path: Path) -> None:
    doc = _burger_doc()
    doc["name"] = "my_bot"
    assert load_model(_write(tmp_path, doc)).name == "my_bot"


def test_unknown_model_name_lists_the_shipped_ones() -> None:
    with pytest.raises(ModelError, match=r"no robot model 'hovercraft'.*jackal.*turtlebot3_burger"):
        load_model("hovercraft")


def test_missing_model_file_is_refused_naming_it(tmp_path: Path) -> None:
    with pytest.raises(ModelError, match=r"nope\.yaml: model file not found"):
        load_model(tmp_path / "nope.yaml")


def test_model_error_is_a_usage_error() -> None:
    assert issubclass(ModelError, UsageError)


def test_shipped_model_errors_name_the_file_as_models_slash_name() -> None:
    with pytest.raises(ModelError, match=r"^models/jackal\.yaml \(overridden\): lidar\.beams: "):
        load_model("jackal", {"lidar": {"beams": 0}})


@pytest.mark.parametrize(
    ("change", "field", "problem"),
    [
        ({"footprint_radius_m": -0.1}, "footprint_radius_m", "must be positive"),
        ({"footprint_radius_m": 0}, "footprint_radius_m", "must be positive"),
        ({"wheel_radius_m": "big"}, "wheel_radius_m", "must be a number"),
        ({"max_linear_mps": float("nan")}, "max_linear_mps", "must be finite"),
        ({"max_angular_rps": True}, "max_angular_rps", "must be a number"),
        ({"max_linear_accel_mps2": 500}, "max_linear_accel_mps2", "at most 100 m/s^2"),
        ({"name": "bad name"}, "name", "must be a name"),
        ({"speed": 1}, "speed", "unknown field"),
        (
            {"battry_capacity_wh": 5},
            "battry_capacity_wh",
            "unknown field 'battry_capacity_wh' (did you mean 'battery_capacity_wh'?",
        ),
    ],
)
def test_a_bad_robot_field_is_refused_naming_file_and_field(
    tmp_path: Path, change: dict[str, Any], field: str, problem: str
) -> None:
    doc = {**_burger_doc(), **change}
    message = _refusal(_write(tmp_path, doc))
    assert message.startswith(f"{tmp_path / 'bot.yaml'}: {field}: ")
    assert problem in message


@pytest.mark.parametrize(
    "field",
    [
        "footprint_radius_m",
        "wheel_radius_m",
        "wheel_separation_m",
        "max_linear_mps",
        "max_angular_rps",
        "max_linear_accel_mps2",
        "max_angular_accel_rps2",
        "battery_capacity_wh",
        "height_m",
    ],
)
def test_a_missing_limit_is_refused(tmp_path: Path, field: str) -> None:
    doc = _burger_doc()
    del doc[field]
    assert _refusal(_write(tmp_path, doc)).endswith(f": {field}: missing")


@pytest.mark.parametrize(
    "field",
    ["beams", "angle_min_rad", "fov_rad", "range_min_m", "range_max_m", "noise_m", "rate_hz"],
)
def test_a_missing_lidar_field_is_refused(tmp_path: Path, field: str) -> None:
    doc = _burger_doc()
    del doc["lidar"][field]
    assert _refusal(_write(tmp_path, doc)).endswith(f": lidar.{field}: missing")


def test_a_model_without_lidar_is_refused(tmp_path: Path) -> None:
    doc = _burger_doc()
    del doc["lidar"]
    assert ": lidar: missing" in _refusal(_write(tmp_path, doc))


@pytest.mark.parametrize(
    ("change", "field", "problem"),
    [
        ({"beams": 0}, "beams", "within [1, 100000]"),
        ({"beams": 360.5}, "beams", "must be an integer"),
        ({"fov_rad": 7.0}, "fov_rad", "at most"),
        ({"fov_rad": 0.0}, "fov_rad", "must be positive"),
        ({"angle_min_rad": -7.0}, "angle_min_rad", "within +-2 pi"),
        ({"range_min_m": -0.1}, "range_min_m", "must be >= 0"),
        ({"range_max_m": 0.1}, "range_max_m", "greater than range_min_m"),
        ({"noise_m": -0.01}, "noise_m", "must be >= 0"),
        ({"rate_hz": 0}, "rate_hz", "must be positive"),
        ({"height_m": -1}, "height_m", "must be positive"),
        ({"colour": "red"}, "colour", "unknown field"),
        ({"rangemax_m": 3.0}, "rangemax_m", "(did you mean 'range_max_m'?"),
        ({"height_m": 50.0}, "height_m", "must be at most 10 m (a lidar 10 m above the floor)"),
        ({"range_max_m": 5000.0}, "range_max_m", "must be at most 1000 m"),
        ({"rate_hz": 1e6}, "rate_hz", "must be at most 1000 Hz"),
        ({"noise_m": 20.0}, "noise_m", "must be at most 10 m"),
        ({"beams": 10**6}, "beams", "within [1, 100000]"),
        # beams not matching the field of view
        ({"angle_increment_rad": 0.01}, "beams", "360 beams over a 360 deg field of view"),
        ({"fov_rad": 3.0, "beams": 1}, "beams", "one beam cannot span"),
    ],
)
def test_a_bad_lidar_field_is_refused_naming_file_and_field(
    tmp_path: Path, change: dict[str, Any], field: str, problem: str
) -> None:
    doc = _burger_doc()
    doc["lidar"].update(change)
    message = _refusal(_write(tmp_path, doc))
    assert message.startswith(f"{tmp_path / 'bot.yaml'}: lidar.{field}: ")
    assert problem in message


def test_beams_matching_a_partial_field_of_view_are_accepted(tmp_path: Path) -> None:
    doc = _burger_doc()
    doc["lidar"].update(beams=181, fov_rad=math.pi, angle_min_rad=-math.pi / 2)
    doc["lidar"]["angle_increment_rad"] = math.radians(1.0)
    lidar = load_model(_write(tmp_path, doc)).lidar
    assert lidar.angle_increment == pytest.approx(math.radians(1.0))
    assert lidar.angle_max_rad == pytest.approx(math.pi / 2)


@pytest.mark.parametrize("text", ["- a list", "name: [unclosed", ""])
def test_a_model_file_that_is_not_a_mapping_is_refused(tmp_path: Path, text: str) -> None:
    path = tmp_path / "bot.yaml"
    path.write_text(text)
    assert _refusal(path).startswith(f"{path}: ")


def test_a_bad_override_is_refused_naming_the_field() -> None:
    with pytest.raises(ModelError, match=r"jackal\.yaml \(overridden\): max_linear_mps: "):
        load_model("jackal", {"max_linear_mps": -1})
    with pytest.raises(ModelError, match=r"\(overridden\): lidar: must be a mapping"):
        load_model("jackal", {"lidar": 3})


@pytest.mark.parametrize(
    ("field", "value", "bound"),
    [
        ("footprint_radius_m", 6.0, "at most 5 m (a ground robot 10 m across)"),
        ("wheel_radius_m", 3.0, "at most 2 m (a wheel 4 m high)"),
        ("wheel_separation_m", 11.0, "at most 10 m (a ground robot 10 m across)"),
        ("max_linear_mps", 1e308, "at most 10 m/s (the fastest velocity a command may carry"),
        ("max_angular_rps", 21.0, "at most 20 rad/s (the fastest turn a command may carry"),
        ("max_linear_accel_mps2", 101.0, "at most 100 m/s^2"),
        ("max_angular_accel_rps2", 101.0, "at most 100 rad/s^2"),
        ("battery_capacity_wh", 1e6, "at most 100000 Wh"),
        ("height_m", 11.0, "at most 10 m (a ground robot 10 m high)"),
    ],
)
def test_each_robot_limit_is_bounded_and_the_refusal_names_the_bound(
    tmp_path: Path, field: str, value: float, bound: str
) -> None:
    doc = {**_burger_doc(), field: value}
    message = _refusal(_write(tmp_path, doc))
    assert message.startswith(f"{tmp_path / 'bot.yaml'}: {field}: must be {bound}")
    assert message.endswith(f"got {value:.6g}")


def test_every_robot_limit_has_a_bound() -> None:
    from common.robotmodel import ROBOT_BOUNDS, ROBOT_FIELDS

    assert set(ROBOT_BOUNDS) == set(ROBOT_FIELDS)


@pytest.mark.parametrize("written", ["1.0e308", "1e308"])
def test_a_number_yaml_1_1_reads_as_text_is_read_as_a_number_and_bounded(
    tmp_path: Path, written: str
) -> None:
    text = (MODELS / "turtlebot3_burger.yaml").read_text()
    text = text.replace("max_linear_mps: 0.22", f"max_linear_mps: {written}")
    path = tmp_path / "bot.yaml"
    path.write_text(text)
    message = _refusal(path)
    assert "max_linear_mps: must be at most 10 m/s" in message
    assert "must be a number" not in message
    # and the same written small is the number it says
    path.write_text(text.replace(f"max_linear_mps: {written}", "max_linear_mps: 5e-1"))
    assert load_model(path).max_linear_mps == 0.5

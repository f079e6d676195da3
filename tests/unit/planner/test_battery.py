"""The battery rules' arithmetic."""

from __future__ import annotations

import pytest

from services.planner.battery_rules import charged_enough, energy_needed, needs_charge, number


def test_energy_needed_is_distance_times_rate_plus_reserve() -> None:
    assert energy_needed(10.0, 0.006, 0.05) == pytest.approx(0.11)
    assert energy_needed(-1.0, 0.006, 0.05) == pytest.approx(0.05)


def test_needs_charge_when_the_charge_will_not_cover_path_and_reserve() -> None:
    assert needs_charge(0.10, 10.0, 0.006, 0.05)  # 0.11 needed
    assert not needs_charge(0.12, 10.0, 0.006, 0.05)
    assert not needs_charge(0.11, 10.0, 0.006, 0.05)  # exactly enough is enough


def test_charged_enough_by_percentage_or_by_margin() -> None:
    assert charged_enough(100.0, 19.98, 100.0, 3.0, 0.5)
    assert not charged_enough(60.0, 1.0, 100.0, 3.0, 0.5)  # 1.0 < 3 x 0.5
    assert charged_enough(60.0, 1.6, 100.0, 3.0, 0.5)
    assert not charged_enough(60.0, 19.0, 100.0, 3.0, None)  # no goal: percentage only
    assert not charged_enough(99.0, 19.0, None, None, 0.1)


def test_number_reads_numeric_params_only() -> None:
    params = {"a": 1, "b": 0.5, "c": "3", "d": True}
    assert number(params, "a") == 1.0 and number(params, "b") == 0.5
    assert number(params, "c") is None and number(params, "d") is None
    assert number(params, "missing") is None

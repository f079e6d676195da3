"""Diff-drive kinematics: directions, arcs, limits, angle wrapping."""

from __future__ import annotations

import math

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from services.sim.robot import BURGER, clamp_command, integrate, normalize_angle, wheel_speeds

pytestmark = pytest.mark.timeout(30)


def run(v: float, w: float, seconds: float, dt: float = 1 / 240) -> tuple[float, float, float]:
    x, y, yaw = 0.0, 0.0, 0.0
    for _ in range(round(seconds / dt)):
        x, y, yaw = integrate(x, y, yaw, v, w, dt)
    return x, y, yaw


def test_forward_moves_along_the_heading() -> None:
    x, y, yaw = run(0.2, 0.0, 1.0)
    assert x == pytest.approx(0.2) and y == pytest.approx(0.0) and yaw == 0.0
    x, y, _ = integrate(0.0, 0.0, math.pi / 2, 0.2, 0.0, 1.0)
    assert x == pytest.approx(0.0, abs=1e-12) and y == pytest.approx(0.2)


def test_positive_angular_turns_counter_clockwise() -> None:
    _, _, yaw = run(0.0, 1.0, 0.5)
    assert yaw == pytest.approx(0.5)  # yaw increases
    x, y, yaw = run(0.2, 1.0, 0.5)
    assert y > 0.0 and x > 0.0  # driving forward while turning left goes left
    _, y, yaw = run(0.2, -1.0, 0.5)
    assert y < 0.0 and yaw == pytest.approx(-0.5)


def test_a_full_circle_comes_back() -> None:
    # 2 pi / w seconds is not a whole number of steps: allow for the fraction of a step
    w = 1.0
    x, y, yaw = run(0.2, w, 2 * math.pi / w)
    assert x == pytest.approx(0.0, abs=1e-3) and y == pytest.approx(0.0, abs=1e-3)
    assert yaw == pytest.approx(0.0, abs=1e-2)


@settings(max_examples=100, deadline=None)
@example(v=0.125, w=1e-9, yaw=0.5, t=1.0)  # a turn rate near 0: the radius form lost precision
@given(
    v=st.floats(-0.22, 0.22),
    w=st.floats(-2.84, 2.84),
    yaw=st.floats(-math.pi, math.pi),
    t=st.floats(0.0, 2.0),
)
def test_one_long_step_equals_many_short_ones(v: float, w: float, yaw: float, t: float) -> None:
    """The step is the exact arc, so the result does not depend on the step size."""
    x1, y1, yaw1 = integrate(0.0, 0.0, yaw, v, w, t)
    x2, y2, yaw2 = 0.0, 0.0, yaw
    for _ in range(8):
        x2, y2, yaw2 = integrate(x2, y2, yaw2, v, w, t / 8)
    assert x1 == pytest.approx(x2, abs=1e-9) and y1 == pytest.approx(y2, abs=1e-9)
    assert math.cos(yaw1 - yaw2) == pytest.approx(1.0)
    assert -math.pi < yaw1 <= math.pi


def test_clamp_and_wheel_speeds() -> None:
    assert clamp_command(BURGER, 1.0, -9.0) == (0.22, -2.84)
    assert clamp_command(BURGER, -0.1, 0.5) == (-0.1, 0.5)
    left, right = wheel_speeds(BURGER, 0.0, 1.0)
    assert right == pytest.approx(0.08 / 0.033) and left == pytest.approx(-right)


@pytest.mark.parametrize(
    "angle, expected",
    [(0.0, 0.0), (math.pi, math.pi), (-math.pi, math.pi), (3 * math.pi / 2, -math.pi / 2)],
)
def test_angles_wrap_into_minus_pi_pi(angle: float, expected: float) -> None:
    assert normalize_angle(angle) == pytest.approx(expected)

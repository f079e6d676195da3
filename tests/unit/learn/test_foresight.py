"""foresight tick by tick: its history of the last seconds, and its machine (watch, back
up, turn, quiet) driven by a model that predicts "no progress" when the robot stopped
moving; silent while there is too little history, near the target, or p is low."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from common.contract.records import LaserScan, Robot
from pnav_learned.features import FEATURES, RANGE_CAP_M, SECTORS
from pnav_learned.foresight import KIND, Foresee, Settings, surroundings
from pnav_learned.history import FORESIGHT_FEATURES, HISTORY_FEATURES, History, sample
from pnav_learned.model import load
from pnav_learned.registry import Found


def foresight_doc(version: str = "f1", bias: float = 3.0, weight: float = -60.0) -> dict[str, Any]:
    """A model of foresight's kind: logit = bias + weight * moved_1s (stopped: p ~ 0.95)."""
    n = len(FORESIGHT_FEATURES)
    w = np.zeros((n, 1))
    w[FORESIGHT_FEATURES.index("moved_1s"), 0] = weight
    return {
        "format": "pnav-mlp/1",
        "name": "stopped",
        "version": version,
        "features": list(FORESIGHT_FEATURES),
        "targets": ["no_progress"],
        "output": "logistic",
        "x_mean": [0.0] * n,
        "x_scale": [1.0] * n,
        "x_min": [-100.0] * n,
        "x_max": [100.0] * n,
        "y_mean": [0.0],
        "y_scale": [1.0],
        "layers": [{"w": w.tolist(), "b": [bias]}],
    }


def found(tmp_path: Path, **kwargs: Any) -> Found:
    path = tmp_path / "foresight.json"
    path.write_text(json.dumps(foresight_doc(**kwargs)))
    return Found(load(path, None, KIND), registered=True)


def decision(target_dist: float = 5.0, ahead: float = 2.0) -> np.ndarray:
    x = np.full(len(FEATURES), RANGE_CAP_M)
    x[SECTORS // 2 - 1 : SECTORS // 2 + 1] = ahead
    x[SECTORS:] = [0.0, 0.0, 0.6, 0.0, target_dist, 0.0]
    return x


CFG = Settings(
    threshold=0.6, min_history_s=1.0, back_up_s=1.0, turn_s=1.0, cooldown_s=3.0, hold_s=0.0
)  # acting at once: the machine's ticks (the hold has its own test)
CLEAR, BLIND = (True, True), (False, False)  # (rear clear, left freer)


def tick(
    f: Foresee,
    model: Found,
    t: float,
    x_m: float,
    around: tuple[bool, bool] = CLEAR,
    target_dist: float = 5.0,
    cfg: Settings = CFG,
) -> Any:
    d = decision(target_dist=5.0 - x_m if target_dist == 5.0 else target_dist)
    s = sample(t, (x_m, 0.0, 0.0), 0.0, (5.0, 0.0), d)
    return f.step(s, d, model, around, cfg)


def test_the_history_measures_the_last_seconds() -> None:
    h = History()
    for k in range(41):  # 4 s at 10 Hz, 0.2 m/s straight ahead, turning 0.1 rad/s
        t = k * 0.1
        d = decision(target_dist=5.0 - 0.2 * t, ahead=2.0 - 0.1 * t)
        h.add(sample(t, (0.2 * t, 0.0, 0.1 * t), 0.2, (5.0, 0.0), d))
    got = dict(zip(HISTORY_FEATURES, h.features(), strict=True))
    assert got["history_s"] == pytest.approx(3.0)
    assert got["moved_1s"] == pytest.approx(0.2, abs=1e-9)
    assert got["moved_3s"] == pytest.approx(0.6, abs=1e-9)
    assert got["progress_3s"] == pytest.approx(0.6, abs=1e-9)
    assert got["turned_3s"] == pytest.approx(0.3, abs=1e-9)
    assert got["speed_mean_3s"] == pytest.approx(0.2)
    assert got["ahead_min_3s"] == pytest.approx(1.6)
    # a new target starts afresh
    h.add(sample(4.1, (0.82, 0.0, 0.0), 0.2, (9.0, 3.0), decision()))
    assert h.features()[0] == 0.0 and len(h.samples) == 1


def test_foresight_waits_predicts_backs_up_turns_then_keeps_quiet(tmp_path: Path) -> None:
    model, f = found(tmp_path), Foresee()
    x, t = 0.0, 0.0
    said: list[tuple[float, Any]] = []
    # 2 s driving at 0.2 m/s: p low, nothing said
    while t < 2.0 - 1e-9:
        said.append((t, tick(f, model, t, x)))
        t, x = round(t + 0.1, 3), x + 0.02
    assert all(c is None for _, c in said)
    assert f.p is not None and f.p < 0.1
    # stopped: within a second moved_1s falls, p crosses 0.6 and the manoeuvre starts
    said = []
    while t < 9.0:
        said.append((t, tick(f, model, t, x)))
        t = round(t + 0.1, 3)
    moves = [(t, c) for t, c in said if c is not None]
    first = moves[0]
    assert 2.0 < first[0] <= 3.0
    assert first[1].linear < 0 and first[1].angular == 0  # backing up first: the rear is clear
    assert "model stopped version f1 (registered)" in first[1].reason
    assert "no progress within 3 s predicted, p 0." in first[1].reason
    assert "confidence 1.00" in first[1].reason
    once = [(t, c) for t, c in moves if t < first[0] + 2.0]  # the first manoeuvre
    backing = [t for t, c in once if c.linear < 0]
    turning = [t for t, c in once if c.angular > 0]  # left: the freer side
    assert backing[-1] - backing[0] == pytest.approx(0.9)
    assert turning[0] == pytest.approx(backing[-1] + 0.1)
    assert turning[-1] - turning[0] == pytest.approx(0.9)
    # quiet for cooldown_s after the turn, though p stays high (the robot still stands)
    end = turning[-1] + 0.1
    assert not [t for t, _ in moves if end <= t < end + CFG.cooldown_s]
    assert [t for t, _ in moves if t >= end + CFG.cooldown_s]  # then it acts again


def test_no_rear_in_sight_turns_only_and_to_the_freer_side(tmp_path: Path) -> None:
    model, f = found(tmp_path), Foresee()
    commands = [tick(f, model, k * 0.1, 1.0, BLIND) for k in range(20)]
    acted = [c for c in commands if c is not None]
    assert acted and all(c.linear == 0 and c.angular < 0 for c in acted)  # right is freer


def test_silent_near_the_target_and_with_little_history(tmp_path: Path) -> None:
    model = found(tmp_path)
    f = Foresee()
    assert all(tick(f, model, k * 0.1, 0.0, target_dist=0.5) is None for k in range(40))
    f = Foresee()
    assert all(tick(f, model, k * 0.1, 0.0) is None for k in range(10))  # < 1 s of history
    low = found(tmp_path, bias=-5.0)  # a model that never fears
    f = Foresee()
    assert all(tick(f, low, k * 0.1, 0.0) is None for k in range(50))


def test_the_rear_is_clear_only_where_the_lidar_sees_it() -> None:
    n = 360
    ranges = np.full(n, 3.0, dtype=np.float32)
    scan = LaserScan(1, "r1", 0.0, -math.pi, 2 * math.pi / n, 0.1, 3.5, ranges)
    assert surroundings(scan, 0.2, 0.2) == (True, True)
    ranges[:10] = 0.3  # straight behind, within reach
    assert surroundings(scan, 0.2, 0.2)[0] is False
    ranges[:10] = 3.0
    ranges[90:170] = 0.4  # the right side crowded
    assert surroundings(scan, 0.2, 0.2) == (True, True)
    ranges[90:170], ranges[190:270] = 3.0, 0.4  # the left crowded
    assert surroundings(scan, 0.2, 0.2) == (True, False)
    jackal = np.full(270, 3.0, dtype=np.float32)  # 270 degrees: no beam behind
    front = LaserScan(2, "r1", 0.0, -3 * math.pi / 4, math.radians(1), 0.1, 3.5, jackal)
    assert surroundings(front, 0.2, 0.2)[0] is False


def test_a_fear_waits_for_the_robot_to_slow_before_it_acts(tmp_path: Path) -> None:
    """A model that always fears (p 0.95 whatever the robot does): while the robot covers
    more than stall_m (0.25 m) a second foresight stays silent; once it has slowed, it acts."""
    model, f = found(tmp_path, weight=0.0), Foresee()
    x, t = 0.0, 0.0
    said: list[tuple[float, Any]] = []
    while t < 3.0 - 1e-9:  # 3 s at 0.5 m/s (CFG acts at once: no hold)
        said.append((t, tick(f, model, t, x)))
        t, x = round(t + 0.1, 3), x + 0.05
    assert f.p is not None and f.p > 0.9
    assert all(c is None for _, c in said)
    while t < 5.0 - 1e-9:  # stopped at x: moved_1s falls by 0.05 m a tick
        said.append((t, tick(f, model, t, x)))
        t = round(t + 0.1, 3)
    first = next((t, c) for t, c in said if c is not None)
    # at 3.5 s the last second holds 0.5 s of motion (0.25 m): 3.6 s is the first below it
    assert first[0] == pytest.approx(3.6)
    assert first[1].linear < 0 and "stalled (under 0.25 m a second) for 0.0 s" in first[1].reason


def test_stall_m_and_hold_s_are_read_from_the_strategy_params() -> None:
    robot = Robot("r1", 2.0, 4.0, 0.22, 270.0)
    assert (Settings.read({}, robot).stall_m, Settings.read({}, robot).hold_s) == (0.25, 1.5)
    got = Settings.read({"foresight_stall_m": 0.5, "foresight_hold_s": 2.0}, robot)
    assert (got.stall_m, got.hold_s) == (0.5, 2.0)


def test_a_fear_acts_only_once_it_and_a_stall_held_hold_s(tmp_path: Path) -> None:
    """An always-fearing model: a 1 s pause (dwa turning in place at a bend) passes in
    silence; a stall that lasts is acted on hold_s (1.5 s) after it began."""
    cfg = replace(CFG, hold_s=1.5)
    model, f = found(tmp_path, weight=0.0), Foresee()
    x, t = 0.0, 0.0
    said: list[tuple[float, Any]] = []

    def drive(until: float, step_m: float) -> None:
        nonlocal x, t
        while t < until - 1e-9:
            said.append((t, tick(f, model, t, x, cfg=cfg)))
            t, x = round(t + 0.1, 3), x + step_m

    drive(2.0, 0.05)  # 0.5 m/s
    drive(3.0, 0.0)  # a 1 s pause (under 0.25 m a second for about 1 s): no act
    drive(5.0, 0.05)
    assert all(c is None for _, c in said)
    drive(9.0, 0.0)  # stopped for good at 5.0 s: under 0.25 m a second from 5.6 s
    first = next(t for t, c in said if c is not None)
    assert first == pytest.approx(7.1)
    assert "stalled (under 0.25 m a second) for 1.5 s" in said[round(first * 10)][1].reason

"""learned_drive with a classifier over dwa's lattice: its likeliest cells are checked as one
batch with dwa's geometry, the likeliest that passes is recommended, and when none passes
dwa decides; the why names the model's version, its confidence and the fallback."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from common.contract.planned_path import PlannedPath
from pnav_learned import lattice
from pnav_learned.candidates import Scene
from pnav_learned.drive import NEXT_K, TOP_K, recommend
from pnav_learned.errors import ModelRefused
from pnav_learned.features import FEATURES
from pnav_learned.model import DRIVE, DRIVE_KINDS, FORMAT, Model, load
from pnav_local import dwa
from tests.unit.learn.test_candidates import BOX, JACKAL, P, odom, scan_of, wall

N = len(FEATURES)
STRAIGHT_ON = lattice.CELLS.index(f"cell_{lattice.LINEAR - 1}_{lattice.ANGULAR // 2}")
HARD_LEFT = lattice.CELLS.index(f"cell_0_{lattice.ANGULAR - 1}")


def lattice_doc(order: list[int], version: str = "lat1") -> dict[str, Any]:
    """A classifier that ranks the cells ``order`` first, in that order, whatever it sees:
    zero weights, descending biases."""
    bias = np.full(len(lattice.CELLS), -20.0)
    for rank, cell in enumerate(order):
        bias[cell] = 10.0 - rank
    return {
        "format": FORMAT,
        "name": "lat",
        "version": version,
        "features": list(FEATURES),
        "targets": list(lattice.CELLS),
        "output": "softmax",
        "x_mean": [0.0] * N,
        "x_scale": [1.0] * N,
        "x_min": [-100.0] * N,
        "x_max": [100.0] * N,
        "y_mean": [0.0] * len(lattice.CELLS),
        "y_scale": [1.0] * len(lattice.CELLS),
        "layers": [{"w": np.zeros((N, len(lattice.CELLS))).tolist(), "b": bias.tolist()}],
    }


def model(tmp_path: Path, order: list[int]) -> Model:
    path = tmp_path / "lat.json"
    path.write_text(json.dumps(lattice_doc(order)))
    return load(path, "lat1", DRIVE_KINDS)


def path_ahead(length: float = 10.0) -> PlannedPath:
    xs = tuple(float(x) for x in np.arange(0.0, length + 1e-9, 0.25))
    return PlannedPath(7, "r1", 0.0, 1, "goal", length, 0.0, xs, (0.0,) * len(xs), length)


def test_the_likeliest_cell_that_passes_is_recommended(tmp_path: Path) -> None:
    m = model(tmp_path, [STRAIGHT_ON, HARD_LEFT])
    scan = scan_of(wall(6.0, -2.0, 2.0))  # far: straight on passes
    said = recommend(m, scan, odom(1.0), JACKAL, path_ahead(), None, P, BOX)
    scene = Scene(scan, odom(1.0), JACKAL, P, 10.0, BOX)
    v, w = lattice.grid(scene.bounds)
    assert (said.linear, said.angular) == (v[STRAIGHT_ON], w[STRAIGHT_ON])
    assert said.inputs is not None
    assert said.inputs["fallback"] is False and said.inputs["checked"] == TOP_K
    assert said.reason.startswith("learned_drive: model lat version lat1, confidence 1.00")
    assert "choice 1 of the" in said.reason and "fallback" not in said.reason


def test_a_refused_first_choice_gives_way_to_the_next_in_the_same_batch(tmp_path: Path) -> None:
    # a post straight ahead 1.2 m off: straight on at speed sweeps the box into it; the hard
    # left turn from a slow start clears it
    m = model(tmp_path, [STRAIGHT_ON, HARD_LEFT])
    scan = scan_of([(1.2, 0.0)])
    said = recommend(m, scan, odom(1.0), JACKAL, path_ahead(), None, P, BOX)
    scene = Scene(scan, odom(1.0), JACKAL, P, 10.0, BOX)
    v, w = lattice.grid(scene.bounds)
    ok, _ = scene.admissible(v[[STRAIGHT_ON, HARD_LEFT]], w[[STRAIGHT_ON, HARD_LEFT]])
    assert ok.tolist() == [False, True]
    assert (said.linear, said.angular) == (v[HARD_LEFT], w[HARD_LEFT])
    assert said.inputs is not None and said.inputs["fallback"] is False
    assert "choice 2 of the" in said.reason


def test_the_next_likeliest_are_checked_only_when_the_first_batch_fails(tmp_path: Path) -> None:
    # a post straight ahead 1.2 m off: the model ranks straight on at the six top speeds
    # first (all refused), then a hard left turn, which passes
    straight = [lattice.CELLS.index(f"cell_{i}_{lattice.ANGULAR // 2}") for i in range(8, 2, -1)]
    m = model(tmp_path, [*straight, HARD_LEFT])
    scan = scan_of([(1.2, 0.0)])
    said = recommend(m, scan, odom(1.0), JACKAL, path_ahead(), None, P, BOX)
    scene = Scene(scan, odom(1.0), JACKAL, P, 10.0, BOX)
    v, w = lattice.grid(scene.bounds)
    assert not scene.admissible(v[straight], w[straight])[0].any()
    assert (said.linear, said.angular) == (v[HARD_LEFT], w[HARD_LEFT])
    assert said.inputs is not None and said.inputs["fallback"] is False
    assert said.inputs["checked"] == TOP_K + NEXT_K
    assert f"choice {TOP_K + 1} of the {TOP_K + NEXT_K} likeliest checked" in said.reason


def test_when_no_likely_cell_passes_dwa_decides_and_the_why_says_so(tmp_path: Path) -> None:
    # three posts ahead: the model ranks first the cells that are refused; dwa's whole
    # window has arcs round them
    posts = [(1.2, 0.0), (1.0, 0.6), (1.0, -0.6)]
    scan, moving, path = scan_of(posts), odom(1.0), path_ahead()
    scene = Scene(scan, moving, JACKAL, P, 10.0, BOX)
    v, w = lattice.grid(scene.bounds)
    ok, _ = scene.admissible(v, w)
    refused = [int(i) for i in np.flatnonzero(~ok) if v[i] > 0.0]
    assert len(refused) >= TOP_K + NEXT_K
    m = model(tmp_path, refused)
    said = recommend(m, scan, moving, JACKAL, path, None, P, BOX)
    choice = dwa.choose(scan, moving, JACKAL, path, P, BOX)
    assert choice is not None
    expected = dwa.command_for(choice, path)
    assert (said.linear, said.angular) == (expected.linear, expected.angular)
    assert said.linear > 0.5 and abs(said.angular) > 0.5  # dwa drives round the posts
    assert said.inputs is not None and said.inputs["fallback"] is True
    assert said.inputs["checked"] == TOP_K + NEXT_K
    assert said.reason.startswith("learned_drive: model lat version lat1, confidence 1.00")
    assert f"none of the {TOP_K + NEXT_K} likeliest cells" in said.reason
    assert "fallback to dwa's own decision; " + expected.reason in said.reason


def test_standing_still_and_repeated_cells_are_not_among_the_checked(tmp_path: Path) -> None:
    # from a standstill with the path's end 0 m away the window has no room for speed: every
    # speed row is the same, and the cell (0, 0) is standing still
    still_cell = lattice.CELLS.index(f"cell_0_{lattice.ANGULAR // 2}")
    m = model(tmp_path, [still_cell, *range(lattice.ANGULAR)])
    scan = scan_of(wall(6.0, -2.0, 2.0))
    said = recommend(m, scan, odom(0.0), JACKAL, path_ahead(0.25), None, P, BOX)
    assert (said.linear, said.angular) != (0.0, 0.0)
    assert said.inputs is not None and said.inputs["checked"] == TOP_K


def test_the_lattice_has_the_window_dwa_samples() -> None:
    # the cells span the window pnav_learned.candidates.bounds computes, corner to corner
    window = (0.5, 1.1, -2.0, 3.0)
    v, w = lattice.grid(window)
    assert (v.min(), v.max(), w.min(), w.max()) == pytest.approx(window)
    assert lattice.nearest((1.1, 0.0), window) == lattice.CELLS.index(
        f"cell_{lattice.LINEAR - 1}_{round(2.0 / 5.0 * (lattice.ANGULAR - 1))}"
    )
    assert len(set(zip(v.tolist(), w.tolist(), strict=True))) == len(lattice.CELLS)
    assert math.isclose(float(v[0]), 0.5) and math.isclose(float(w[0]), -2.0)


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        ({"features": list(FEATURES[:-1])}, "made for other features"),
        ({"targets": list(lattice.CELLS[:-1])}, "targets 152 targets, expected"),
        ({"output": "identity"}, "output 'identity', learned_drive needs 'softmax'"),
    ],
)
def test_a_mismatched_lattice_model_is_refused(
    tmp_path: Path, change: dict[str, Any], reason: str
) -> None:
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(lattice_doc([STRAIGHT_ON]) | change))
    with pytest.raises(ModelRefused, match=reason):
        load(path, None, DRIVE_KINDS)


def test_a_lattice_model_is_no_regression_model(tmp_path: Path) -> None:
    # a scenario that runs only proposals' regressions refuses a lattice classifier
    path = tmp_path / "lat.json"
    path.write_text(json.dumps(lattice_doc([STRAIGHT_ON])))
    with pytest.raises(ModelRefused, match="153 targets, expected"):
        load(path, None, DRIVE)


async def test_learned_drive_resolves_either_kind_and_refuses_others(tmp_path: Path) -> None:
    # the scenario's params name a lattice file or a regression file: each is loaded as what
    # it is; a file of neither kind is refused with the reason, and the scenario stands down
    from typing import cast

    from common.controller_core.scenario import Host
    from pnav_learned import registry
    from pnav_learned.drive import LearnedDrive
    from tests.unit.learn.test_model_refusals import Register, model_doc

    host = cast(Host, Register())
    lat = tmp_path / "lat.json"
    lat.write_text(json.dumps(lattice_doc([STRAIGHT_ON])))
    reg = tmp_path / "reg.json"
    reg.write_text(json.dumps(model_doc()))
    kind = LearnedDrive.kind
    found = await registry.resolve(host, {"learned_model": str(lat)}, "learned", kind)
    assert not isinstance(found, str) and found.model.lattice
    found = await registry.resolve(host, {"learned_model": str(reg)}, "learned", kind)
    assert not isinstance(found, str) and not found.model.lattice
    other = tmp_path / "other.json"
    other.write_text(json.dumps(lattice_doc([STRAIGHT_ON]) | {"targets": ["no_progress"]}))
    refused = await registry.resolve(host, {"learned_model": str(other)}, "learned", kind)
    assert isinstance(refused, str) and "targets ['no_progress'], expected 153 cells" in refused

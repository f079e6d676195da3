"""map_server maps: PGM reading (P5, P2, 16-bit, comments), trinary classification, negate,
the bottom-up grid, and the rectangles that become wall bodies."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from common.errors import WorldError
from services.sim.mapserver import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    OccupancyGrid,
    encode_pgm,
    load_map,
    parse_pgm,
)
from tests.unit.sim.conftest import write_map

pytestmark = pytest.mark.timeout(30)

# 4 columns x 3 rows, row 0 is the top of the image:
#   top:    occupied free     free     unknown
#   middle: free     occupied free     free
#   bottom: free     free     free     occupied
IMAGE = np.array(
    [
        [0, 254, 254, 205],
        [254, 0, 254, 254],
        [254, 254, 254, 0],
    ],
    dtype=np.uint8,
)
# the grid is bottom-up: row 0 is the image's last row
EXPECTED = np.array(
    [
        [FREE, FREE, FREE, OCCUPIED],
        [FREE, OCCUPIED, FREE, FREE],
        [OCCUPIED, FREE, FREE, UNKNOWN],
    ],
    dtype=np.uint8,
)


def test_p5_map_has_known_cells_row_zero_at_the_bottom(tmp_path: Path) -> None:
    grid = load_map(write_map(tmp_path, IMAGE, origin=[-1.0, 2.0, 0.0]))
    assert (grid.width, grid.height) == (4, 3)
    np.testing.assert_array_equal(grid.cells, EXPECTED)
    # the contract's bytes: row-major, bottom row first
    assert grid.to_bytes() == EXPECTED.tobytes()
    assert grid.to_bytes()[:4] == bytes([0, 0, 0, 100])
    # the lower-left cell's centre is half a cell from the origin
    assert grid.value_at(-1.0 + 0.025, 2.0 + 0.025) == FREE
    assert grid.value_at(-1.0 + 0.025, 2.0 + 2 * 0.05 + 0.025) == OCCUPIED  # top-left pixel
    assert grid.value_at(-1.5, 2.0) is None
    assert grid.origin == (-1.0, 2.0, 0.0)


def test_p2_ascii_reads_the_same_as_p5(tmp_path: Path) -> None:
    (tmp_path / "map.pgm").write_bytes(encode_pgm(IMAGE, binary=False))
    path = write_map(tmp_path, IMAGE)
    (tmp_path / "map.pgm").write_bytes(encode_pgm(IMAGE, binary=False))
    assert (tmp_path / "map.pgm").read_bytes().startswith(b"P2")
    np.testing.assert_array_equal(load_map(path).cells, EXPECTED)


def test_header_comments_and_16_bit_depth() -> None:
    p2 = b"P2\n# made by hand\n2 1\n# depth\n65535\n0 65535\n"
    np.testing.assert_array_equal(parse_pgm(p2), [[0, 255]])
    p5 = b"P5 # comment\n2 1 65535\n" + np.array([65535, 0], dtype=">u2").tobytes()
    np.testing.assert_array_equal(parse_pgm(p5), [[255, 0]])


def test_negate_swaps_black_and_white(tmp_path: Path) -> None:
    grid = load_map(write_map(tmp_path, np.array([[0, 255, 128]], dtype=np.uint8), negate=1))
    # negate: p = value / 255, so black (0) is free and white (255) occupied
    assert grid.cells.tolist() == [[FREE, OCCUPIED, UNKNOWN]]


def test_thresholds_follow_trinary_semantics(tmp_path: Path) -> None:
    # p = (255 - v) / 255: v=89 -> p=0.651 > 0.65 occupied; v=90 -> 0.647 unknown;
    # v=205 -> 0.196 (not < 0.196) unknown; v=206 -> 0.192 free
    pixels = np.array([[89, 90, 205, 206]], dtype=np.uint8)
    assert load_map(write_map(tmp_path, pixels)).cells.tolist() == [
        [OCCUPIED, UNKNOWN, UNKNOWN, FREE]
    ]


@pytest.mark.parametrize(
    "data, problem",
    [
        (b"P6\n1 1\n255\n\x00\x00\x00", "not a PGM"),
        (b"P5\n4 4\n255\n\x00", "too short"),
        (b"P5\n4", "truncated"),
        (b"P2\n2 1\n255\n0 x\n", "non-numeric"),
    ],
)
def test_bad_images_fail_with_the_file_and_problem(
    tmp_path: Path, data: bytes, problem: str
) -> None:
    path = write_map(tmp_path, IMAGE)
    (tmp_path / "map.pgm").write_bytes(data)
    with pytest.raises(WorldError) as err:
        load_map(path)
    assert str(path) in str(err.value)
    assert problem in str(err.value)


def grid_of(cells: np.ndarray) -> OccupancyGrid:
    return OccupancyGrid(cells=cells, resolution=0.1, origin=(0.0, 0.0, 0.0), source="test")


@settings(max_examples=60, deadline=None)
@given(
    arrays(
        np.uint8,
        st.tuples(st.integers(1, 12), st.integers(1, 12)),
        elements=st.sampled_from([FREE, OCCUPIED, UNKNOWN]),
    )
)
def test_rectangles_cover_exactly_the_occupied_cells(cells: np.ndarray) -> None:
    cover = np.zeros(cells.shape, dtype=np.int32)
    for col0, row0, col1, row1 in grid_of(cells).occupied_rectangles():
        assert col0 < col1 and row0 < row1
        cover[row0:row1, col0:col1] += 1
    # every occupied cell in exactly one rectangle, nothing else covered
    np.testing.assert_array_equal(cover, (cells == OCCUPIED).astype(np.int32))


def test_rectangles_merge_a_walled_room_into_four_boxes() -> None:
    cells = np.full((40, 60), FREE, dtype=np.uint8)
    cells[0, :] = cells[-1, :] = OCCUPIED
    cells[:, 0] = cells[:, -1] = OCCUPIED
    rects = grid_of(cells).occupied_rectangles()
    assert len(rects) == 4


def test_occupied_near_uses_the_disc_not_its_box() -> None:
    cells = np.full((20, 20), FREE, dtype=np.uint8)
    cells[10, 10] = OCCUPIED  # the square [1.0, 1.1] x [1.0, 1.1]
    grid = grid_of(cells)
    assert grid.occupied_near(1.05, 1.05, 0.01)
    assert grid.occupied_near(0.95, 1.05, 0.06)
    assert not grid.occupied_near(0.95, 1.05, 0.04)
    # diagonal: the corner (1.0, 1.0) is 0.0707 from (0.95, 0.95)
    assert not grid.occupied_near(0.95, 0.95, 0.07)
    assert grid.occupied_near(0.95, 0.95, 0.072)

"""A minimal PNG writer (8-bit RGB, no filtering), so pictures need no imaging library.

A PNG is the 8-byte signature and chunks, each ``length | type | data | CRC-32``: IHDR (size
and pixel format), IDAT (the zlib-deflated rows, each led by its filter type byte, 0 = none)
and IEND.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
import numpy.typing as npt

SIGNATURE = b"\x89PNG\r\n\x1a\n"
RGB = 2  # IHDR colour type


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def encode_png(rgb: npt.NDArray[np.uint8]) -> bytes:
    """The PNG of an image of shape (height, width, 3), row 0 at the top."""
    image = np.ascontiguousarray(rgb, dtype=np.uint8)
    if image.ndim != 3 or image.shape[2] != 3 or image.shape[0] == 0 or image.shape[1] == 0:
        raise ValueError(f"expected a non-empty (height, width, 3) image, got {image.shape}")
    height, width = image.shape[:2]
    header = struct.pack(">IIBBBBB", width, height, 8, RGB, 0, 0, 0)
    rows = np.zeros((height, 1 + width * 3), dtype=np.uint8)  # column 0: filter type 0
    rows[:, 1:] = image.reshape(height, width * 3)
    return (
        SIGNATURE
        + _chunk(b"IHDR", header)
        + _chunk(b"IDAT", zlib.compress(rows.tobytes(), 9))
        + _chunk(b"IEND", b"")
    )


def write_png(path: Path, rgb: npt.NDArray[np.uint8]) -> None:
    path.write_bytes(encode_png(rgb))

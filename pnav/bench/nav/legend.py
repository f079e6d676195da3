"""A colour key drawn under a picture: a swatch and a word or two per colour.

Pictures are written with no imaging library (pnav/bench/nav/png.py), so the words are drawn
with a 3 x 5 pixel font of lower-case letters, blown up ``scale`` times.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from common.errors import UsageError

Colour = tuple[int, int, int]
Image = npt.NDArray[np.uint8]

BACKGROUND: Colour = (255, 255, 255)
INK: Colour = (40, 40, 40)

# 3 x 5 glyphs, one string per row, "#" inked
_FONT: dict[str, tuple[str, ...]] = {
    "a": (".#.", "#.#", "###", "#.#", "#.#"),
    "b": ("##.", "#.#", "##.", "#.#", "##."),
    "c": (".##", "#..", "#..", "#..", ".##"),
    "d": ("##.", "#.#", "#.#", "#.#", "##."),
    "e": ("###", "#..", "##.", "#..", "###"),
    "f": ("###", "#..", "##.", "#..", "#.."),
    "g": (".##", "#..", "#.#", "#.#", ".##"),
    "h": ("#.#", "#.#", "###", "#.#", "#.#"),
    "i": ("###", ".#.", ".#.", ".#.", "###"),
    "j": ("..#", "..#", "..#", "#.#", ".#."),
    "k": ("#.#", "#.#", "##.", "#.#", "#.#"),
    "l": ("#..", "#..", "#..", "#..", "###"),
    "m": ("#.#", "###", "###", "#.#", "#.#"),
    "n": ("##.", "#.#", "#.#", "#.#", "#.#"),
    "o": (".#.", "#.#", "#.#", "#.#", ".#."),
    "p": ("##.", "#.#", "##.", "#..", "#.."),
    "q": (".#.", "#.#", "#.#", "##.", ".##"),
    "r": ("##.", "#.#", "##.", "#.#", "#.#"),
    "s": (".##", "#..", ".#.", "..#", "##."),
    "t": ("###", ".#.", ".#.", ".#.", ".#."),
    "u": ("#.#", "#.#", "#.#", "#.#", "###"),
    "v": ("#.#", "#.#", "#.#", "#.#", ".#."),
    "w": ("#.#", "#.#", "###", "###", "#.#"),
    "x": ("#.#", "#.#", ".#.", "#.#", "#.#"),
    "y": ("#.#", "#.#", ".#.", ".#.", ".#."),
    "z": ("###", "..#", ".#.", "#..", "###"),
    " ": ("...", "...", "...", "...", "..."),
}
GLYPH_W, GLYPH_H = 3, 5


def text(words: str, scale: int = 2, colour: Colour = INK) -> Image:
    """The image of ``words`` (lower-case letters and spaces), one pixel between letters."""
    if scale < 1:
        raise UsageError(f"scale must be at least 1, got {scale}")
    unknown = sorted({c for c in words if c not in _FONT})
    if unknown:
        raise UsageError(f"the legend font has no {''.join(unknown)!r}: letters a-z and spaces")
    width = max(1, len(words) * (GLYPH_W + 1) - 1)
    ink = np.zeros((GLYPH_H, width), dtype=bool)
    for i, char in enumerate(words):
        glyph = np.array([[c == "#" for c in row] for row in _FONT[char]], dtype=bool)
        ink[:, i * (GLYPH_W + 1) : i * (GLYPH_W + 1) + GLYPH_W] = glyph
    ink = np.repeat(np.repeat(ink, scale, axis=0), scale, axis=1)
    out = np.empty((*ink.shape, 3), dtype=np.uint8)
    out[...] = BACKGROUND
    out[ink] = colour
    return out


def with_legend(image: Image, key: Sequence[tuple[Colour, str]], scale: int = 2) -> Image:
    """``image`` with a strip under it: for each (colour, words) a swatch and the words, left
    to right, wrapped onto as many lines as the image's width needs."""
    width = image.shape[1]
    pad, line_h = 3 * scale, (GLYPH_H + 4) * scale
    entries = [(colour, text(words, scale)) for colour, words in key]
    lines: list[list[tuple[Colour, Image]]] = [[]]
    used = pad
    for colour, label in entries:
        need = line_h + 2 * scale + label.shape[1] + 2 * pad
        if lines[-1] and used + need > width:
            lines.append([])
            used = pad
        lines[-1].append((colour, label))
        used += need
    strip = np.empty((len(lines) * (line_h + pad) + pad, width, 3), dtype=np.uint8)
    strip[...] = BACKGROUND
    for n, line in enumerate(lines):
        top, left = pad + n * (line_h + pad), pad
        for colour, label in line:
            _paste(strip, top, left, np.full((line_h, line_h, 3), colour, dtype=np.uint8))
            left += line_h + 2 * scale
            _paste(strip, top + (line_h - label.shape[0]) // 2, left, label)
            left += label.shape[1] + 2 * pad
    return np.concatenate([image, strip], axis=0)


def _paste(onto: Image, top: int, left: int, piece: Image) -> None:
    """Copy ``piece`` at (top, left), clipped to ``onto``."""
    h = min(piece.shape[0], onto.shape[0] - top)
    w = min(piece.shape[1], onto.shape[1] - left)
    if h > 0 and w > 0:
        onto[top : top + h, left : left + w] = piece[:h, :w]

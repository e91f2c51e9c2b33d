"""High-frequency albedo textures for the anti-aliasing scenes (linear float32, (h, w, 3)).

The raster renderer samples textures bilinearly without mip-maps, so a texture whose texels are
smaller than a pixel on screen aliases (moire on minified checkerboards, broken glyph strokes on
minified text) unless the filter anti-aliases it. Texture row 0 is the top (v = 1).
"""

from __future__ import annotations

import numpy as np


def checker(size: int, squares: int, dark=(0.08, 0.08, 0.08), light=(0.85, 0.85, 0.85)) -> np.ndarray:
    """A ``squares x squares`` checkerboard of ``size x size`` texels (texel (0, 0) light)."""
    cell = np.arange(size) * squares // size
    odd = (cell[:, None] + cell[None, :]) % 2 == 1
    return np.ascontiguousarray(np.where(odd[..., None], np.asarray(dark, np.float32),
                                         np.asarray(light, np.float32)), np.float32)


def glyphs(size: int, lines: int, seed: int, ink=(0.05, 0.05, 0.08), paper=(0.9, 0.88, 0.8)) -> np.ndarray:
    """Text-like rows of random 5x7 glyphs (one-texel strokes) on ``paper``.

    ``lines`` text lines fill the texture; each glyph cell is 6 x 9 texels (5 x 7 glyph, one
    column and two rows of spacing); words are separated by blank cells.
    """
    rng = np.random.default_rng(seed)
    out = np.empty((size, size, 3), np.float32)
    out[:] = paper
    cell_h = size // lines
    top = max((cell_h - 9) // 2, 0)
    for line in range(lines):
        y0 = line * cell_h + top
        if y0 + 7 > size:
            break
        x = 1
        while x + 5 <= size:
            if rng.random() < 0.18:  # a space between words
                x += 6
                continue
            glyph = rng.random((7, 5)) < 0.42
            glyph[:, rng.integers(0, 5)] |= rng.random() < 0.5  # a vertical stem in half the glyphs
            out[y0:y0 + 7, x:x + 5][glyph] = ink
            x += 6
    return out


def stripes(size: int, count: int, a=(0.75, 0.1, 0.08), b=(0.9, 0.85, 0.75)) -> np.ndarray:
    """``count`` diagonal stripe pairs (warning-tape pattern)."""
    idx = np.arange(size)
    band = ((idx[:, None] + idx[None, :]) * count // size) % 2 == 0
    return np.ascontiguousarray(np.where(band[..., None], np.asarray(a, np.float32), np.asarray(b, np.float32)),
                                np.float32)


def planks(size: int, boards: int, seed: int, base=(0.45, 0.3, 0.18)) -> np.ndarray:
    """Wooden boards with thin dark gaps and fine grain lines along u."""
    rng = np.random.default_rng(seed)
    v = (np.arange(size) + 0.5) * boards / size
    board = np.floor(v).astype(int)
    gap = (v - board) < 0.08
    tone = 0.8 + 0.4 * rng.random(boards)
    grain = 0.85 + 0.15 * np.sin(np.arange(size)[None, :] * 0.9 + 7.0 * rng.random((size, 1)))
    out = np.asarray(base, np.float32) * (tone[board][:, None] * grain)[..., None]
    out[gap] = 0.04
    return np.ascontiguousarray(out, np.float32)

"""Procedural albedo textures as small linear float32 (h, w, 3) arrays.

Texture row 0 is the top of the image (v = 1), as OpenImageIO reads image files. Values are
multiplied by the material's ``albedo`` by the renderers, so textures here carry pattern and
tint in [0, 1].
"""

from __future__ import annotations

import numpy as np


def checker(size: int = 64, squares: int = 8, dark=(0.1, 0.1, 0.1), light=(0.9, 0.9, 0.9)) -> np.ndarray:
    """A ``squares x squares`` checkerboard of ``size x size`` texels; texel (0, 0) is ``light``."""
    cell = np.arange(size) * squares // size
    mask = (cell[:, None] + cell[None, :]) % 2 == 1
    out = np.where(mask[..., None], np.asarray(dark, np.float32), np.asarray(light, np.float32))
    return np.ascontiguousarray(out, np.float32)


def value_noise(size: int, cells: int, rng: np.random.Generator) -> np.ndarray:
    """Tileable smooth value noise in [0, 1], (size, size) float32, ``cells`` lattice cells per side."""
    lattice = rng.random((cells, cells))
    x = np.arange(size) * cells / size
    i0 = np.floor(x).astype(int)
    f = x - i0
    f = f * f * (3 - 2 * f)
    i1 = (i0 + 1) % cells
    rows0, rows1 = lattice[i0], lattice[i1]
    top = rows0[:, i0] * (1 - f)[None, :] + rows0[:, i1] * f[None, :]
    bot = rows1[:, i0] * (1 - f)[None, :] + rows1[:, i1] * f[None, :]
    return (top * (1 - f)[:, None] + bot * f[:, None]).astype(np.float32)


def stone(size: int = 128, seed: int = 1, base=(0.62, 0.56, 0.48)) -> np.ndarray:
    """Weathered stone: a few octaves of value noise modulating ``base``."""
    rng = np.random.default_rng(seed)
    n = sum(value_noise(size, c, rng) * w for c, w in ((4, 0.5), (8, 0.3), (32, 0.2)))
    return np.ascontiguousarray(np.asarray(base, np.float32) * (0.75 + 0.35 * n[..., None]), np.float32)


def tiles(size: int = 128, count: int = 4, grout: float = 0.06, seed: int = 2,
          colors=((0.55, 0.33, 0.22), (0.62, 0.42, 0.28))) -> np.ndarray:
    """Square floor tiles (``count`` per side) in two alternating tones with dark grout lines."""
    rng = np.random.default_rng(seed)
    t = (np.arange(size) + 0.5) * count / size
    cell = np.floor(t).astype(int)
    frac = t - cell
    line = (frac < grout) | (frac > 1 - grout)
    grout_mask = line[:, None] | line[None, :]
    parity = (cell[:, None] + cell[None, :]) % 2
    c = np.asarray(colors, np.float32)[parity]
    c = c * (0.85 + 0.3 * value_noise(size, 16, rng)[..., None])
    out = np.where(grout_mask[..., None], np.float32(0.12), c)
    return np.ascontiguousarray(out, np.float32)


def bricks(size: int = 128, rows: int = 8, seed: int = 3, base=(0.58, 0.28, 0.2)) -> np.ndarray:
    """Running-bond bricks with mortar, ``rows`` courses per texture."""
    rng = np.random.default_rng(seed)
    y = (np.arange(size) + 0.5) * rows / size
    course = np.floor(y).astype(int)
    x = (np.arange(size) + 0.5) * rows / (2 * size)
    xs = x[None, :] + 0.5 * (course[:, None] % 2)
    brick = np.floor(xs).astype(int)
    mortar = ((y - course) < 0.1)[:, None] | ((xs - brick) < 0.05)
    tint = 0.8 + 0.4 * rng.random((rows + 1, rows + 2))[course[:, None] % (rows + 1), brick % (rows + 2)]
    c = np.asarray(base, np.float32) * tint[..., None]
    out = np.where(mortar[..., None], np.float32(0.7), c)
    return np.ascontiguousarray(out, np.float32)


def stripes(size: int = 64, count: int = 6, a=(0.7, 0.1, 0.08), b=(0.85, 0.7, 0.2)) -> np.ndarray:
    """Vertical stripes for cloth banners."""
    band = (np.arange(size) * count // size) % 2 == 1
    row = np.where(band[:, None], np.asarray(b, np.float32), np.asarray(a, np.float32))
    return np.ascontiguousarray(np.broadcast_to(row[None], (size, size, 3)), np.float32)


def windows(size: int = 128, cols: int = 4, rows: int = 4, wall=(0.7, 0.66, 0.6),
            glass=(0.05, 0.07, 0.09)) -> np.ndarray:
    """A facade: a ``cols x rows`` grid of dark window panes on a wall colour."""
    t = (np.arange(size) + 0.5) / size
    fx = (t * cols) % 1.0
    fy = (t * rows) % 1.0
    pane = ((fy > 0.25) & (fy < 0.85))[:, None] & ((fx > 0.2) & (fx < 0.8))[None, :]
    out = np.where(pane[..., None], np.asarray(glass, np.float32), np.asarray(wall, np.float32))
    return np.ascontiguousarray(out, np.float32)

"""Writing pictures of results: tone-mapped 8-bit PNGs through OpenImageIO."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def encode_srgb(image: np.ndarray) -> np.ndarray:
    """Linear radiance clamped to [0, 1] and sRGB-encoded, float64: the harness's display mapping.

    Exposure 1 (no scaling before the clamp), no tone curve besides the clamp: the mapping of
    SSIM, FLIP and the ``display_*`` error metrics, and of the pictures a run writes.
    """
    x = np.clip(np.nan_to_num(np.asarray(image, np.float64)), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def srgb_slope(image: np.ndarray) -> np.ndarray:
    """Derivative of :func:`encode_srgb` with respect to linear radiance, elementwise (float64).

    12.92 on the linear toe, ``1.055 / 2.4 * x^(1/2.4 - 1)`` above it, and 0 outside [0, 1]
    where the display mapping clamps.
    """
    x = np.nan_to_num(np.asarray(image, np.float64))
    inside = (x >= 0.0) & (x <= 1.0)
    toe = x <= 0.0031308
    curve = 1.055 / 2.4 * np.power(np.maximum(x, 0.0031308), 1.0 / 2.4 - 1.0)
    return np.where(inside, np.where(toe, 12.92, curve), 0.0)


def display_variance(reference: np.ndarray, variance: np.ndarray) -> np.ndarray:
    """The variance of a reference's displayed values, from its linear variance (delta method).

    ``Var[encode_srgb(r)] ~ encode_srgb'(r)^2 Var[r]``: first order in the reference's standard
    error, which the profiles keep at a few percent; float64, same shape.
    """
    return srgb_slope(reference) ** 2 * np.asarray(variance, np.float64)


def tonemap(image: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    """Linear HDR radiance to 8-bit sRGB (exposure, clamp, then the sRGB curve)."""
    return np.round(encode_srgb(np.asarray(image, np.float64) * exposure) * 255.0).astype(np.uint8)


def write_png(path: str | Path, image: np.ndarray, exposure: float = 1.0) -> Path:
    """Write an (H, W, 3) linear image as a PNG; returns the path."""
    import OpenImageIO as oiio

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    pixels = tonemap(image, exposure)
    out = oiio.ImageOutput.create(str(path))
    if out is None:
        raise OSError(f"cannot write {path}: {oiio.geterror()}")
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], "uint8")
    out.open(str(path), spec)
    out.write_image(pixels)
    out.close()
    return path


def write_pictures(folder: str | Path, name: str, output: np.ndarray, noisy: np.ndarray, noisy_name: str,
                   reference: np.ndarray | None) -> None:
    """PNGs of a filter's output, its noisy input and the reference (``--pictures``)."""
    folder = Path(folder)
    write_png(folder / f"{name}.png", output)
    write_png(folder / f"{noisy_name}.png", noisy)
    if reference is not None:
        write_png(folder / "reference.png", reference)

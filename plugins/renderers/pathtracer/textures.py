"""Reading the image files of Mitsuba texture descriptions as Mitsuba 3 reads them."""

from __future__ import annotations

import numpy as np

from harness import srgb_to_linear


def read_description_texture(path: str, *, raw: bool = False) -> np.ndarray:
    """An image as a float32 (h, w, 3) array of the values Mitsuba 3's ``bitmap`` texture looks up.

    Colour channels are read without associating alpha (the alpha channel itself is dropped, as
    Mitsuba 3 does); one channel (or grey + alpha) is repeated to RGB. Integer images are decoded
    from sRGB unless ``raw``; float images are used as stored. A missing file gives mid grey (the
    loader has warned about it).
    """
    import OpenImageIO as oiio

    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), config)
    if inp is None:
        return np.full((1, 1, 3), 0.5, np.float32)
    try:
        spec = inp.spec()
        pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
        is_float = spec.format.basetype in (oiio.FLOAT, oiio.HALF, oiio.DOUBLE)
    finally:
        inp.close()
    pixels = np.asarray(pixels, np.float32).reshape(spec.height, spec.width, spec.nchannels)
    pixels = np.repeat(pixels[..., :1], 3, axis=2) if spec.nchannels < 3 else pixels[..., :3]
    if not (is_float or raw):
        pixels = srgb_to_linear(pixels)
    return np.ascontiguousarray(np.clip(np.nan_to_num(pixels, nan=0.0), 0.0, None), np.float32)

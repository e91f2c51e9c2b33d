"""Where in its pixel each camera ray starts: the renderer's declared sampling conventions.

**Noisy frames** (``render``, the adaptive ``sampler``): every sample of a pixel starts at one
first hit, as a rasterized G-buffer has it, so colour and G-buffer agree pixel for pixel. That
hit is through the pixel centre, or with ``jitter`` through the centre shifted by the frame's
Halton (2, 3) offset (:func:`harness.halton_jitter`: point ``(frame mod 16) + 1`` of the sequence, in
[-0.5, 0.5) pixels, the raster renderer's and TAA engines' sequence), the same for every pixel
of the frame.

**References** (``accumulate``, ``reference``): with ``reference_pixel="area"`` (the default)
each sample has its own camera ray through a point of the pixel's area, so the reference is the
pixel's box-filtered mean, as Mitsuba 3 renders with a ``box`` reconstruction filter. The points
are stratified in blocks of four samples: samples ``4k .. 4k + 3`` of a pixel fall one in each
quarter of the pixel (in an order rotated at random per block), each uniformly within its
quarter (:func:`subpixel`). Every sample is uniform over the pixel, so a sum over any samples
is unbiased; blocks are independent of each other, so the reference's batch-means variance
(:mod:`harness.references`, batches of whole blocks) stays an estimate of independent batches.
``reference_pixel="centre"`` keeps pixel-centre references (the convention before issue 30).
"""

from __future__ import annotations

from numba import njit

from .rng import stream_key, uniform

#: samples per stratified block of a pixel-area reference (2 x 2 quarters)
BLOCK = 4
#: random-number dimensions of the sub-pixel position (far above the path's 8 per bounce)
SUBPIXEL_DIM = 1 << 20
REFERENCE_PIXELS = ("area", "centre")


@njit(cache=True, error_model="numpy", inline="always")
def subpixel(seed, frame, pixel, sample):
    """Offset (x right, y down) in [-0.5, 0.5)^2 from the pixel centre of sample ``sample`` of a pixel-area
    reference (see the module docstring)."""
    key = stream_key(seed, frame, pixel, sample)
    block_key = stream_key(seed, frame, pixel, sample - sample % BLOCK)
    quarter = (sample % BLOCK + int(uniform(block_key, SUBPIXEL_DIM + 2) * BLOCK)) % BLOCK
    x = (quarter % 2 + uniform(key, SUBPIXEL_DIM)) * 0.5
    y = (quarter // 2 + uniform(key, SUBPIXEL_DIM + 1)) * 0.5
    return x - 0.5, y - 0.5


__all__ = ["BLOCK", "REFERENCE_PIXELS", "subpixel"]

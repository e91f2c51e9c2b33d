"""Per-pixel input preparation (albedo demodulation, planar G-buffer) and remodulation.

Planar layouts: signals ``(S, 3, H, W)``, normals ``(3, H, W)``, motion ``(2, H, W)``. ``S`` is 2
when the frame carries ``indirect`` (filtered separately from the rest of the light), else 1.

Bad input is made harmless here, in the pass that reads it anyway (the rules are listed in the
README): a pixel with a negative object id, a non-finite depth, or a zero or non-finite normal
is background; non-finite radiance counts as 0; a NaN albedo as 1, a pixel whose albedo is
below ``UNDEMODULATED_BELOW`` in every component is not demodulated; motion that is not finite
points outside the image (no history).

The ``valid`` plane says what a pixel is: 0 background, :data:`DEMODULATED` a surface whose
signals are irradiance (radiance over albedo), :data:`UNDEMODULATED` a surface whose signals are
radiance. The two kinds never mix: every filter pass (reprojection, the variance estimate, the
à-trous iterations) takes a neighbour or a history tap only where its kind equals the pixel's.
Mixed, a radiance pixel would receive its neighbours' irradiance unscaled (remodulated by 1, not
by their albedo), which can be many times their colour where an albedo component is small (on
the living room: a black pixel of albedo 0 turned 60 times its neighbourhood's brightest input).
"""

from __future__ import annotations

import math

from numba import njit

#: demodulated values are clamped to this magnitude so that sums of a few of them stay finite in float32
F32_BIG = 1.0e37
#: depths are clamped to this magnitude (differences, slopes and tolerances stay finite)
DEPTH_MAX = 1.0e30
#: the largest albedo used for demodulation and remodulation: albedo is a reflectance, and a
#: pixel whose albedo exceeds its neighbours' by a factor k gets their irradiance times k (with
#: 1e6 here, a 5 % sprinkle of 3.4e38 albedo gave outputs 1e6 times the largest input colour)
ALBEDO_MAX = 1.0
#: a pixel whose largest albedo component is below this is not demodulated (its albedo counts as 1):
#: renderers report albedo 0 on conductors (Mitsuba's albedo AOV) while their colour is not, and
#: dividing by the floor ``albedo_epsilon`` made that colour 1000 times brighter, spread by the
#: à-trous passes onto the surfaces around it (see the README)
UNDEMODULATED_BELOW = 0.01
#: ``valid`` codes of the two kinds of surface pixel (0 is background)
DEMODULATED = 1
UNDEMODULATED = 2


@njit(cache=True, inline="always")
def pixel_kind(surface, largest):
    """The ``valid`` code of a pixel: 0 where not ``surface``, else :data:`UNDEMODULATED` where its
    largest albedo component ``largest`` is below :data:`UNDEMODULATED_BELOW`, else
    :data:`DEMODULATED`."""
    if not surface:
        return 0
    return DEMODULATED if largest >= UNDEMODULATED_BELOW else UNDEMODULATED


@njit(cache=True, inline="always")
def demodulation_albedo(a, largest, albedo_eps):
    """The albedo component ``a`` used for demodulation: 1 where NaN or where the pixel's largest
    component ``largest`` is below :data:`UNDEMODULATED_BELOW`, else ``a`` within
    ``[albedo_eps, ALBEDO_MAX]``."""
    if a != a or not largest >= UNDEMODULATED_BELOW:
        return 1.0
    return min(max(a, albedo_eps), ALBEDO_MAX)


@njit(cache=True, inline="always")
def largest_albedo(a0, a1, a2):
    """The largest albedo component of a pixel, a NaN component counting as 1 (as it is used)."""
    a0 = 1.0 if a0 != a0 else a0
    a1 = 1.0 if a1 != a1 else a1
    a2 = 1.0 if a2 != a2 else a2
    return max(a0, max(a1, a2))


@njit(cache=True, inline="always")
def finite_or_zero(x):
    """``x`` where it is finite, else 0."""
    return x if math.isfinite(x) else 0.0


@njit(cache=True, inline="always")
def prepare_pixel(i, j, color, indirect, nsig, emission, has_emission, albedo_in, normal_in, depth_in,
                  obj_in, motion_in, albedo_eps, sig, albedo, valid, depth, normal, obj, motion):
    """Demodulate pixel (i, j) and write its planar G-buffer.

    ``color`` is the authority: with two signals the first is ``color - indirect - emission``
    (the direct light when the split is consistent) and the second ``indirect``; with one, the
    first is ``color - emission``. Each is divided by ``max(albedo, albedo_eps)``, or by 1 where the
    pixel's largest albedo component is below :data:`UNDEMODULATED_BELOW` (no amplification of
    the colour of conductors, whose albedo renderers report as 0). The emitted
    radiance is not filtered: :func:`remodulate_pixel` adds it back.

    Parameters
    ----------
    i, j : int
        Row and column.
    color, indirect : ndarray (H, W, 3) float32
        The frame's radiance and its indirect part (``indirect`` is read only when ``nsig == 2``).
    nsig : int
        Number of signals, 1 or 2.
    emission : ndarray (H, W, 3) float32
        Radiance emitted by the first-hit surface (read only when ``has_emission``).
    has_emission : bool
        Whether the frame has an ``emission`` channel.
    albedo_in, normal_in : ndarray (H, W, 3) float32
    depth_in : ndarray (H, W) float32
    obj_in : ndarray (H, W) int32
    motion_in : ndarray (H, W, 2) float32
    albedo_eps : float
        Demodulation divides by ``max(albedo, albedo_eps)``.
    sig, albedo, valid, depth, normal, obj, motion : ndarray
        Outputs: ``(S, 3, H, W)``, ``(3, H, W)``, ``(H, W)`` uint8, ``(H, W)``, ``(3, H, W)``,
        ``(H, W)`` int32, ``(2, H, W)``.
    """
    h = depth_in.shape[0]
    w = depth_in.shape[1]
    z = depth_in[i, j]
    oid = obj_in[i, j]
    n0 = normal_in[i, j, 0]
    n1 = normal_in[i, j, 1]
    n2 = normal_in[i, j, 2]
    ok = (oid >= 0 and math.isfinite(z) and math.isfinite(n0) and math.isfinite(n1) and math.isfinite(n2)
          and (n0 != 0.0 or n1 != 0.0 or n2 != 0.0))
    largest = largest_albedo(albedo_in[i, j, 0], albedo_in[i, j, 1], albedo_in[i, j, 2])
    valid[i, j] = pixel_kind(ok, largest)
    obj[i, j] = oid
    depth[i, j] = min(max(z, -DEPTH_MAX), DEPTH_MAX) if ok else 0.0
    normal[0, i, j] = min(max(n0, -1.0), 1.0) if ok else 0.0
    normal[1, i, j] = min(max(n1, -1.0), 1.0) if ok else 0.0
    normal[2, i, j] = min(max(n2, -1.0), 1.0) if ok else 0.0
    lim = float(h + w + 4)
    for k in range(2):
        m = motion_in[i, j, k]
        motion[k, i, j] = min(max(m, -lim), lim) if m == m else lim  # NaN: outside, no history
    for c in range(3):
        a = demodulation_albedo(albedo_in[i, j, c], largest, albedo_eps)
        albedo[c, i, j] = a
        if ok:
            # float64 arithmetic (also under the CUDA simulator: no float32 overflow warning)
            e = float(finite_or_zero(emission[i, j, c])) if has_emission else 0.0
            rest = float(finite_or_zero(color[i, j, c])) - e
            if nsig == 2:
                ind = float(finite_or_zero(indirect[i, j, c]))
                rest -= ind
                sig[1, c, i, j] = min(max(ind / a, -F32_BIG), F32_BIG)
            sig[0, c, i, j] = min(max(rest / a, -F32_BIG), F32_BIG)
        else:
            for s in range(nsig):
                sig[s, c, i, j] = 0.0


@njit(cache=True, inline="always")
def remodulate_pixel(i, j, sig, albedo, valid, color, emission, has_emission, out):
    """Write ``albedo * sum of filtered signals + emission`` at pixel (i, j), the input colour on
    background.

    Parameters
    ----------
    sig : ndarray (S, 3, H, W) float32
        Filtered demodulated signals.
    albedo : ndarray (3, H, W) float32
        The albedo used by :func:`prepare_pixel`.
    valid : ndarray (H, W) uint8
    color : ndarray (H, W, 3) float32
        The input colour (copied on background pixels).
    emission : ndarray (H, W, 3) float32
        Emitted radiance added back unfiltered (read only when ``has_emission``; not finite: 0).
    has_emission : bool
    out : ndarray (H, W, 3) float32
    """
    if valid[i, j] == 0:
        for c in range(3):
            out[i, j, c] = color[i, j, c]
        return
    for c in range(3):
        acc = 0.0
        for s in range(sig.shape[0]):
            acc += sig[s, c, i, j]
        e = finite_or_zero(emission[i, j, c]) if has_emission else 0.0
        out[i, j, c] = min(max(albedo[c, i, j] * acc + e, -F32_BIG), F32_BIG)

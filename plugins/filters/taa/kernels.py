"""Per-pixel body of the TAA resolve, shared by the CPU and CUDA backends.

:func:`resolve_px` is plain Python over scalars and arrays computing output pixel ``(i, j)``.
:mod:`.cpu` compiles it with ``numba.njit`` and loops over rows in parallel; :mod:`.cuda`
compiles the very same function as a ``numba.cuda`` device function called by one thread per
pixel, so the two backends run the same float64 arithmetic.

The body calls no Python helper (both backends must compile it), so small formulas such as the
Catmull-Rom tap weights are written inline.

Colour spaces: with ``weighted`` (luminance weighting, Karis 2014) every colour is compressed to
``c / (1 + Y)`` before it enters the statistics, the clipping and the blend, and the blended
result is expanded by ``1 / (1 - Y')`` (the exact inverse for one colour); ``Y`` is the luma of
YCoCg, ``(R + 2G + B) / 4``. The neighbourhood statistics and the clipping run in YCoCg
(Karis 2014): ``Y = R/4 + G/2 + B/4``, ``Co = R/2 - B/2``, ``Cg = -R/4 + G/2 - B/4``.
"""

from __future__ import annotations

import math

#: clipping modes of the history (``clip_mode``)
CLIP_NONE, CLIP_MINMAX, CLIP_VARIANCE = 0, 1, 2
#: history fetch filters (``fetch``)
FETCH_BILINEAR, FETCH_CATMULL_ROM = 0, 1
#: the exponent of UE4's Gaussian fit of a Blackman-Harris window of radius 1 pixel (Karis 2014)
BLACKMAN_HARRIS_FIT = 2.29
#: smallest ``1 - Y'`` of the expansion (colours above ~1e12 saturate instead of overflowing)
EXPAND_FLOOR = 1e-12


def resolve_px(i, j, color, depth, object_id, motion, jx, jy, hist, hist_depth, hist_id, has_history,
               alpha, gamma, clip_mode, weighted, reconstruct, fetch, dilate, depth_tolerance, out):
    """One output pixel of TAA: reconstruct, reproject, validate, fetch, clip, blend.

    Parameters
    ----------
    i, j : int
        Output pixel (row, column); its centre is image point ``(j, i)``.
    color : (H, W, 3) float32
        Aliased colour; pixel (i, j) was shaded at ``(j + jx, i + jy)``.
    depth : (H, W) float32
        View depth, ``inf`` on background.
    object_id : (H, W) int32
    motion : (H, W, 2) float32
        Harness motion: from the pixel centre to the surface's position in the previous frame's
        unjittered image (it includes the current jitter on surface pixels).
    jx, jy : float
        This frame's jitter in pixels.
    hist, hist_depth, hist_id : arrays (H, W, 3), (H, W), (H, W)
        The previous output and the previous frame's depth and object ids.
    has_history : bool
        False after a reset or a camera cut: the output is the reconstructed current colour.
    alpha : float
        Weight of the current frame in the blend (history ``1 - alpha``).
    gamma : float
        Half-width of the variance box in standard deviations.
    clip_mode : int
        :data:`CLIP_NONE`, :data:`CLIP_MINMAX` (3x3 min/max box) or :data:`CLIP_VARIANCE`
        (Salvi's ``mu +- gamma sigma`` box); the history is clipped towards the box centre.
    weighted : bool
        Luminance weighting (see the module docstring).
    reconstruct : bool
        Reconstruct the current colour at the pixel centre from the 3x3 samples with the
        Blackman-Harris fit ``exp(-2.29 d^2)`` of each sample's distance ``d`` to the centre
        (the samples sit at the jittered positions); False uses the pixel's own sample.
    fetch : int
        :data:`FETCH_CATMULL_ROM` (16 taps) or :data:`FETCH_BILINEAR`.
    dilate : bool
        Take the motion of the closest depth in the 3x3 neighbourhood (Karis 2014), so edges
        move with the foreground.
    depth_tolerance : float
        Relative depth difference of the disocclusion test: the reprojected position must lie
        inside the image, and among the previous frame's 3x3 pixels around it one must show the
        pixel's own surface, or the surface its (dilated) motion came from, with the same object
        id and a depth within the tolerance, or show something farther than that surface by more
        than the tolerance (then the surface newly covers it, which is not a disocclusion).
    out : (H, W, 3) float32
    """
    h = color.shape[0]
    w = color.shape[1]
    s_y = 0.0
    s_co = 0.0
    s_cg = 0.0
    q_y = 0.0
    q_co = 0.0
    q_cg = 0.0
    lo_y = math.inf
    lo_co = math.inf
    lo_cg = math.inf
    hi_y = -math.inf
    hi_co = -math.inf
    hi_cg = -math.inf
    cur_r = 0.0
    cur_g = 0.0
    cur_b = 0.0
    w_sum = 0.0
    bi = i
    bj = j
    best = depth[i, j]
    for dy in range(-1, 2):
        ii = min(max(i + dy, 0), h - 1)
        for dx in range(-1, 2):
            jj = min(max(j + dx, 0), w - 1)
            r = max(float(color[ii, jj, 0]), 0.0)
            g = max(float(color[ii, jj, 1]), 0.0)
            b = max(float(color[ii, jj, 2]), 0.0)
            if weighted:
                k = 1.0 / (1.0 + 0.25 * r + 0.5 * g + 0.25 * b)
                r *= k
                g *= k
                b *= k
            y = 0.25 * r + 0.5 * g + 0.25 * b
            co = 0.5 * r - 0.5 * b
            cg = -0.25 * r + 0.5 * g - 0.25 * b
            s_y += y
            s_co += co
            s_cg += cg
            q_y += y * y
            q_co += co * co
            q_cg += cg * cg
            lo_y = min(lo_y, y)
            lo_co = min(lo_co, co)
            lo_cg = min(lo_cg, cg)
            hi_y = max(hi_y, y)
            hi_co = max(hi_co, co)
            hi_cg = max(hi_cg, cg)
            if reconstruct:
                ox = dx + jx
                oy = dy + jy
                wt = math.exp(-BLACKMAN_HARRIS_FIT * (ox * ox + oy * oy))
                cur_r += wt * r
                cur_g += wt * g
                cur_b += wt * b
                w_sum += wt
            elif dx == 0 and dy == 0:
                cur_r = r
                cur_g = g
                cur_b = b
                w_sum = 1.0
            if dilate and depth[ii, jj] < best:
                best = depth[ii, jj]
                bi = ii
                bj = jj
    cur_r /= w_sum
    cur_g /= w_sum
    cur_b /= w_sum

    valid = has_history
    px = 0.0
    py = 0.0
    if valid:
        d_ref = float(depth[bi, bj])
        mx = float(motion[bi, bj, 0])
        my = float(motion[bi, bj, 1])
        if not math.isinf(d_ref):  # surface motion follows the jittered sample: remove the jitter
            mx -= jx
            my -= jy
        px = j + mx
        py = i + my
        valid = False
        if math.isfinite(px) and math.isfinite(py) and -0.5 < px < w - 0.5 and -0.5 < py < h - 0.5:
            # disocclusion test on the previous frame's 3x3 pixels around the reprojected
            # position, for the pixel's own surface and for the one its motion came from: the
            # history is kept if one of those pixels showed the same surface (object id, depth
            # within the tolerance) or something farther away (the surface now covers it: not a
            # disocclusion); it is rejected when all of them showed something nearer or another
            # object at the same depth (the surface was hidden)
            xn = int(math.floor(px + 0.5))
            yn = int(math.floor(py + 0.5))
            for ty in range(-1, 2):
                yy = min(max(yn + ty, 0), h - 1)
                for tx in range(-1, 2):
                    xx = min(max(xn + tx, 0), w - 1)
                    d_h = float(hist_depth[yy, xx])
                    for k in range(2):
                        if k == 0:
                            target = object_id[i, j]
                            d_cur = float(depth[i, j])
                        else:
                            target = object_id[bi, bj]
                            d_cur = d_ref
                        if math.isinf(d_cur):
                            if math.isinf(d_h):
                                valid = True
                        elif d_h > d_cur * (1.0 + depth_tolerance):
                            valid = True
                        elif hist_id[yy, xx] == target and abs(d_h - d_cur) <= depth_tolerance * d_cur:
                            valid = True

    if valid:
        x0 = int(math.floor(px))
        y0 = int(math.floor(py))
        fx = px - x0
        fy = py - y0
        h_r = 0.0
        h_g = 0.0
        h_b = 0.0
        if fetch == FETCH_CATMULL_ROM:
            wx0 = fx * (-0.5 + fx * (1.0 - 0.5 * fx))
            wx1 = 1.0 + fx * fx * (-2.5 + 1.5 * fx)
            wx2 = fx * (0.5 + fx * (2.0 - 1.5 * fx))
            wx3 = fx * fx * (-0.5 + 0.5 * fx)
            wy0 = fy * (-0.5 + fy * (1.0 - 0.5 * fy))
            wy1 = 1.0 + fy * fy * (-2.5 + 1.5 * fy)
            wy2 = fy * (0.5 + fy * (2.0 - 1.5 * fy))
            wy3 = fy * fy * (-0.5 + 0.5 * fy)
        else:
            wx0 = 0.0
            wx1 = 1.0 - fx
            wx2 = fx
            wx3 = 0.0
            wy0 = 0.0
            wy1 = 1.0 - fy
            wy2 = fy
            wy3 = 0.0
        for ty in range(4):
            wy = wy0 if ty == 0 else (wy1 if ty == 1 else (wy2 if ty == 2 else wy3))
            if wy == 0.0:
                continue
            yy = min(max(y0 + ty - 1, 0), h - 1)
            for tx in range(4):
                wx = wx0 if tx == 0 else (wx1 if tx == 1 else (wx2 if tx == 2 else wx3))
                if wx == 0.0:
                    continue
                xx = min(max(x0 + tx - 1, 0), w - 1)
                wt = wx * wy
                h_r += wt * hist[yy, xx, 0]
                h_g += wt * hist[yy, xx, 1]
                h_b += wt * hist[yy, xx, 2]
        h_r = max(h_r, 0.0)  # Catmull-Rom overshoots; negative radiance is clamped
        h_g = max(h_g, 0.0)
        h_b = max(h_b, 0.0)
        if weighted:
            k = 1.0 / (1.0 + 0.25 * h_r + 0.5 * h_g + 0.25 * h_b)
            h_r *= k
            h_g *= k
            h_b *= k
        top = max(hi_y, 0.25 * h_r + 0.5 * h_g + 0.25 * h_b)
        if clip_mode != CLIP_NONE:
            if clip_mode == CLIP_VARIANCE:
                c_y = s_y / 9.0
                c_co = s_co / 9.0
                c_cg = s_cg / 9.0
                e_y = gamma * math.sqrt(max(q_y / 9.0 - c_y * c_y, 0.0))
                e_co = gamma * math.sqrt(max(q_co / 9.0 - c_co * c_co, 0.0))
                e_cg = gamma * math.sqrt(max(q_cg / 9.0 - c_cg * c_cg, 0.0))
            else:
                c_y = 0.5 * (lo_y + hi_y)
                c_co = 0.5 * (lo_co + hi_co)
                c_cg = 0.5 * (lo_cg + hi_cg)
                e_y = 0.5 * (hi_y - lo_y)
                e_co = 0.5 * (hi_co - lo_co)
                e_cg = 0.5 * (hi_cg - lo_cg)
            v_y = 0.25 * h_r + 0.5 * h_g + 0.25 * h_b - c_y
            v_co = 0.5 * h_r - 0.5 * h_b - c_co
            v_cg = -0.25 * h_r + 0.5 * h_g - 0.25 * h_b - c_cg
            # clip the segment from the box centre to the history at the box (1 = inside)
            t = 1.0
            if abs(v_y) > e_y:
                t = min(t, e_y / abs(v_y))
            if abs(v_co) > e_co:
                t = min(t, e_co / abs(v_co))
            if abs(v_cg) > e_cg:
                t = min(t, e_cg / abs(v_cg))
            if t < 1.0:
                y = c_y + t * v_y
                co = c_co + t * v_co
                cg = c_cg + t * v_cg
                h_r = max(y + co - cg, 0.0)
                h_g = max(y + cg, 0.0)
                h_b = max(y - co - cg, 0.0)
        o_r = alpha * cur_r + (1.0 - alpha) * h_r
        o_g = alpha * cur_g + (1.0 - alpha) * h_g
        o_b = alpha * cur_b + (1.0 - alpha) * h_b
        # clamping after the clip can lift the luma a little: never above the brightest input
        y = 0.25 * o_r + 0.5 * o_g + 0.25 * o_b
        if y > top:
            k = top / y
            o_r *= k
            o_g *= k
            o_b *= k
    else:
        o_r = cur_r
        o_g = cur_g
        o_b = cur_b
    if weighted:
        k = 1.0 / max(1.0 - (0.25 * o_r + 0.5 * o_g + 0.25 * o_b), EXPAND_FLOOR)
        o_r *= k
        o_g *= k
        o_b *= k
    out[i, j, 0] = min(max(o_r, 0.0), 3.0e38)
    out[i, j, 1] = min(max(o_g, 0.0), 3.0e38)
    out[i, j, 2] = min(max(o_b, 0.0), 3.0e38)

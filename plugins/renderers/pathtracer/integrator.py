"""The path-tracing integrator: next-event estimation with multiple importance sampling.

A noisy frame's paths all start at the pixel's first hit (the surface point of the G-buffer,
traced once through the pixel centre or the frame's jittered point), so colour and features agree
pixel for pixel; a pixel-area reference traces each sample's own camera ray and first hit
(:func:`accumulate_area`; conventions in :mod:`.pixel_sampling`). At each vertex the
integrator samples a light (next-event estimation) and the BSDF, and weights the two strategies
with the power heuristic (Veach and Guibas, SIGGRAPH 1995). Paths stop at ``max_depth`` segments
(Mitsuba's convention: 1 = emitters seen directly, 2 = direct lighting) and are Russian-rouletted
after ``rr_depth`` bounces with survival probability ``min(max throughput, 0.95)``.

``strategy``: 0 = MIS (default), 1 = light sampling only (emitters reached by BSDF sampling count
only after delta bounces), 2 = BSDF sampling only. All three estimate the same image.

A sample's contribution is "direct" when its path has at most two segments (emission seen at the
first hit, light arriving at the first hit), "indirect" otherwise.

Random numbers: dimension ``8 * bounce + j`` of the stream :func:`.rng.stream_key` (seed, frame,
pixel, sample); per-pixel sums are accumulated in sample order in float64 on top of the sums
passed in, so continuing a pixel's samples later gives bit-identical sums.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from harness import kernels

from .borrow import borrowed
from .bsdf import (
    F_A,
    F_B,
    I_CHILD0,
    I_CHILD1,
    I_TEX_A,
    I_TEX_B,
    TWOSIDED,
    bsdf_eval,
    bsdf_sample,
    is_delta,
    is_transmissive,
)
from .lights import DELTA_LIGHT, infinite_radiance, infinite_radiance_pdf, sample_light
from .materials import HAS_MASK, ONE_SIDED_EMISSION
from .pixel_sampling import subpixel
from .rng import stream_key, uniform
from .shading import bump_normal, bump_shadowing, node_colour, resolve, transparent
from .traverse import closest_hit, occluded, stack_size
from .vecmath import cross, dot, normalize, onb, to_local, to_world

MIS, LIGHT_ONLY, BSDF_ONLY = 0, 1, 2
STRATEGIES = {"mis": MIS, "light": LIGHT_ONLY, "bsdf": BSDF_ONLY}
TASK = 64  # pixels per task of the parallel loops, taken in turn by the threads (see harness.kernels.take)


@njit(cache=True, error_model="numpy", inline="always")
def surface(tri, b1, b2, tri_v, tri_n, tri_uv):
    """Position, unit geometric normal (winding order), unit shading normal and uv of a hit."""
    b0 = 1.0 - b1 - b2
    v0 = (np.float64(tri_v[tri, 0]), np.float64(tri_v[tri, 1]), np.float64(tri_v[tri, 2]))
    v1 = (np.float64(tri_v[tri, 3]), np.float64(tri_v[tri, 4]), np.float64(tri_v[tri, 5]))
    v2 = (np.float64(tri_v[tri, 6]), np.float64(tri_v[tri, 7]), np.float64(tri_v[tri, 8]))
    p = (b0 * v0[0] + b1 * v1[0] + b2 * v2[0], b0 * v0[1] + b1 * v1[1] + b2 * v2[1],
         b0 * v0[2] + b1 * v1[2] + b2 * v2[2])
    ng = normalize(cross((v1[0] - v0[0], v1[1] - v0[1], v1[2] - v0[2]),
                         (v2[0] - v0[0], v2[1] - v0[1], v2[2] - v0[2])))
    ns = normalize((b0 * tri_n[tri, 0] + b1 * tri_n[tri, 3] + b2 * tri_n[tri, 6],
                    b0 * tri_n[tri, 1] + b1 * tri_n[tri, 4] + b2 * tri_n[tri, 7],
                    b0 * tri_n[tri, 2] + b1 * tri_n[tri, 5] + b2 * tri_n[tri, 8]))
    if ns[0] == 0.0 and ns[1] == 0.0 and ns[2] == 0.0:
        ns = ng
    u = b0 * tri_uv[tri, 0] + b1 * tri_uv[tri, 2] + b2 * tri_uv[tri, 4]
    v = b0 * tri_uv[tri, 1] + b1 * tri_uv[tri, 3] + b2 * tri_uv[tri, 5]
    return p, ng, ns, u, v


@njit(cache=True, error_model="numpy", inline="always")
def trace_sample(key, ray_o, ray_d, tri, b1, b2, geom, mats, lights, lp, eps, max_depth, rr_depth,
                 strategy, emissive, stack_n, stack_t):
    """Radiance of one path starting at a known first hit.

    ``emissive``: whether any material emits (:func:`any_emission`). Where none does, the last
    segment of a path (whose end point would only add its emission) is an any-hit query that
    asks whether the path escapes, about twice as fast as a closest-hit query; the radiance is
    the same, bit for bit.

    Returns
    -------
    tuple
        ``(r, g, b, dr, dg, db, shadow_rays, shadow_hits)``: radiance, its direct part, and the
        first hit's light samples and how many of them reached their light.
    """
    tri_v, tri_n, tri_uv, tri_mat, nodes_f, nodes_i, tri_front = geom
    mat_root, mat_flags, mat_emit, node_kind, nf, ni, tables, tex_data, tex_off, tex_w, tex_h, tex_uv = mats
    # the tables the called BSDF and material functions read, without reference counting (see .borrow)
    node_kind, nf, ni, tables = borrowed(node_kind), borrowed(nf), borrowed(ni), borrowed(tables)
    tex_data, tex_off, tex_w = borrowed(tex_data), borrowed(tex_off), borrowed(tex_w)
    tex_h, tex_uv = borrowed(tex_h), borrowed(tex_uv)
    emit_tri, emit_cdf, tri_light_pdf, env_img, cdf_rows, cdf_cols = lights
    lr = lg = lb = 0.0
    dr = dg = db = 0.0
    vrays = 0
    vhits = 0
    d = ray_d
    if tri < 0:
        if max_depth >= 1:
            lr, lg, lb = infinite_radiance(d, lp, env_img)
        return lr, lg, lb, lr, lg, lb, vrays, vhits
    tr = tg = tb = 1.0
    prev_pdf = 1.0
    prev_delta = True
    seg_len = 0.0
    bounce = 0
    while True:
        p, ng, ns, tu, tv = surface(tri, b1, b2, tri_v, tri_n, tri_uv)
        m = tri_mat[tri]
        wo = (-d[0], -d[1], -d[2])
        cos_go = dot(ng, wo)
        er, eg, eb = np.float64(mat_emit[m, 0]), np.float64(mat_emit[m, 1]), np.float64(mat_emit[m, 2])
        if (er > 0.0 or eg > 0.0 or eb > 0.0) and (
                (mat_flags[m] & ONE_SIDED_EMISSION) == 0 or tri_front[tri] * cos_go > 0.0):
            w = 1.0
            if not prev_delta:
                if strategy == LIGHT_ONLY:
                    w = 0.0
                elif strategy == MIS:
                    cos_l = abs(cos_go)
                    pl = tri_light_pdf[tri] * seg_len * seg_len / cos_l if cos_l > 0.0 else 0.0
                    w = prev_pdf * prev_pdf / (prev_pdf * prev_pdf + pl * pl)
            lr += tr * er * w
            lg += tg * eg * w
            lb += tb * eb * w
            if bounce <= 1:
                dr += tr * er * w
                dg += tg * eg * w
                db += tb * eb * w
        if bounce + 2 > max_depth:
            break
        base = 8 * bounce
        front = dot(ns, wo) > 0.0
        root = mat_root[m]
        bump = -1
        bump_outside = False
        if node_kind[root] < TWOSIDED:  # a bare BSDF, or twosided around one: no walk, no random number
            leaf, two_sided = root, False
        elif node_kind[root] == TWOSIDED and node_kind[ni[root, I_CHILD0]] < TWOSIDED and (
                front or ni[root, I_CHILD1] == ni[root, I_CHILD0]):
            leaf, two_sided = ni[root, I_CHILD0], True
        else:
            leaf, two_sided, bump, bump_outside = resolve(root, front, uniform(key, base + 7), tu, tv, node_kind,
                                                          nf, ni, tex_data, tex_off, tex_w, tex_h, tex_uv)
        if leaf < 0:  # through a mask: a null interaction, as a delta lobe of weight 1
            wi = d
            wr = wg = wb = 1.0
            pdf = 1.0
            dlt = True
            side = -eps if cos_go > 0.0 else eps
        else:
            kind = node_kind[leaf]
            transmissive = is_transmissive(kind)
            if transmissive:
                n = ns
            else:
                if not (two_sided or front):
                    break  # a one-sided BSDF seen from behind is black
                if cos_go < 0.0:
                    ng = (-ng[0], -ng[1], -ng[2])
                    cos_go = -cos_go
                n = ns if dot(ns, ng) >= 0.0 else (-ns[0], -ns[1], -ns[2])
                if dot(n, wo) <= 1e-9:
                    n = ng
            n0 = n
            if bump >= 0:  # the bump-mapped normal (a bumpmap around twosided: seen from behind, its mirror)
                n = bump_normal(bump, two_sided and bump_outside and not front, n, ng, wo, tri, tu, tv, tri_v,
                                tri_uv, nf, ni, tex_data, tex_off, tex_w, tex_h, tex_uv)
            ca = node_colour(leaf, I_TEX_A, F_A, tu, tv, nf, ni, tex_data, tex_off, tex_w, tex_h, tex_uv)
            cb = node_colour(leaf, I_TEX_B, F_B, tu, tv, nf, ni, tex_data, tex_off, tex_w, tex_h, tex_uv)
            t_ax, s_ax = onb(n)
            wo_l = to_local(wo, t_ax, s_ax, n)
            if strategy != BSDF_ONLY and not is_delta(kind):
                ld, ldist, le, lpdf, ltri = sample_light(
                    uniform(key, base), uniform(key, base + 1), uniform(key, base + 2), p, lp, tri_v, tri_mat,
                    mat_emit, mat_flags, tri_front, emit_tri, emit_cdf, tri_light_pdf, env_img, cdf_rows, cdf_cols)
                if lpdf > 0.0:
                    if bounce == 0:
                        vrays += 1
                    side_l = dot(ld, ng)
                    if side_l > 0.0 or (transmissive and side_l < 0.0):
                        wi_l = to_local(ld, t_ax, s_ax, n)
                        fr, fg, fb, fpdf = bsdf_eval(kind, leaf, nf, ni, tables, ca, cb, wo_l, wi_l)
                        if bump >= 0:
                            sh = bump_shadowing(n0, n, ld)
                            fr, fg, fb = fr * sh, fg * sh, fb * sh
                        visible = False
                        if (fr > 0.0 or fg > 0.0 or fb > 0.0) or bounce == 0:
                            off = eps if side_l > 0.0 else -eps
                            so = (p[0] + ng[0] * off, p[1] + ng[1] * off, p[2] + ng[2] * off)
                            tmax = ldist * (1.0 - 1e-4) if ldist < np.inf else np.inf
                            visible = not occluded(so[0], so[1], so[2], ld[0], ld[1], ld[2], tmax, ltri,
                                                   tri_v, nodes_f, nodes_i, stack_n, stack_t)
                        if visible:
                            if bounce == 0:
                                vhits += 1
                            if fr > 0.0 or fg > 0.0 or fb > 0.0:
                                w = 1.0
                                if strategy == MIS and ltri != DELTA_LIGHT:
                                    w = lpdf * lpdf / (lpdf * lpdf + fpdf * fpdf)
                                k = w / lpdf
                                cr, cg, cb_ = tr * fr * le[0] * k, tg * fg * le[1] * k, tb * fb * le[2] * k
                                lr += cr
                                lg += cg
                                lb += cb_
                                if bounce == 0:
                                    dr += cr
                                    dg += cg
                                    db += cb_
            wi_l, wr, wg, wb, pdf, dlt = bsdf_sample(kind, leaf, nf, ni, tables, ca, cb, wo_l,
                                                     uniform(key, base + 3), uniform(key, base + 4),
                                                     uniform(key, base + 5))
            if not (wr > 0.0 or wg > 0.0 or wb > 0.0):
                break
            wi = to_world(wi_l, t_ax, s_ax, n)
            if bump >= 0:
                sh = bump_shadowing(n0, n, wi)
                wr, wg, wb = wr * sh, wg * sh, wb * sh
                if sh <= 0.0:
                    break
            cos_gi = dot(wi, ng)
            if (wi_l[2] * wo_l[2] > 0.0) != (cos_gi * cos_go > 0.0) or cos_gi == 0.0:
                break
            side = eps if cos_gi > 0.0 else -eps
        tr *= wr
        tg *= wg
        tb *= wb
        if bounce + 1 >= rr_depth:
            q = min(max(tr, tg, tb), 0.95)
            if uniform(key, base + 6) >= q:
                break
            tr /= q
            tg /= q
            tb /= q
        o = (p[0] + ng[0] * side, p[1] + ng[1] * side, p[2] + ng[2] * side)
        if emissive or bounce + 3 <= max_depth:
            hit, t, hb1, hb2 = closest_hit(o[0], o[1], o[2], wi[0], wi[1], wi[2], np.inf, tri,
                                           tri_v, nodes_f, nodes_i, stack_n, stack_t)
        else:  # the last segment where no surface emits: only whether it escapes matters
            if occluded(o[0], o[1], o[2], wi[0], wi[1], wi[2], np.inf, tri, tri_v, nodes_f, nodes_i, stack_n,
                        stack_t):
                break
            hit, t, hb1, hb2 = -1, np.inf, 0.0, 0.0
        if hit < 0:
            er, eg, eb, pl = infinite_radiance_pdf(wi, lp, env_img, cdf_rows, cdf_cols)
            w = 1.0
            if not dlt:
                if strategy == LIGHT_ONLY:
                    w = 0.0
                elif strategy == MIS:
                    w = pdf * pdf / (pdf * pdf + pl * pl)
            lr += tr * er * w
            lg += tg * eg * w
            lb += tb * eb * w
            if bounce == 0:
                dr += tr * er * w
                dg += tg * eg * w
                db += tb * eb * w
            break
        d = wi
        tri, b1, b2 = hit, hb1, hb2
        prev_pdf = pdf
        prev_delta = dlt
        seg_len = t
        bounce += 1
    return lr, lg, lb, dr, dg, db, vrays, vhits


@njit(cache=True, error_model="numpy")
def any_emission(mat_emit):
    """True if some material has a positive emission component (the test of :func:`trace_sample`)."""
    for m in range(mat_emit.shape[0]):
        if mat_emit[m, 0] > 0.0 or mat_emit[m, 1] > 0.0 or mat_emit[m, 2] > 0.0:
            return True
    return False


@njit(cache=True, error_model="numpy", inline="always")
def pixel_ray(i, width, height, eye, right, up, forward, tan_half, jx, jy):
    """Origin and unit direction of the ray through the centre of row-major pixel ``i`` shifted by
    ``(jx, jy)`` pixels (x right, y down), with the operations (and so the rounding) of
    :meth:`harness.CameraPath.primary_rays`."""
    row = i // width
    col = i - row * width
    sx = ((col + 0.5 + jx) / width * 2.0 - 1.0) * tan_half * (width / height)
    sy = (1.0 - (row + 0.5 + jy) / height * 2.0) * tan_half
    dx = forward[0] + sx * right[0] + sy * up[0]
    dy = forward[1] + sx * right[1] + sy * up[1]
    dz = forward[2] + sx * right[2] + sy * up[2]
    norm = math.sqrt(dx * dx + dy * dy + dz * dz)
    return eye, (dx / norm, dy / norm, dz / norm)


@njit(cache=True, error_model="numpy", inline="always")
def first_hit(o, d, geom, mats, stack_n, stack_t):
    """The first hit of a camera ray: ``(triangle or -1, b1, b2, distance)``.

    The closest surface that a sample can stop at: surfaces where a ``mask``'s opacity is 0 are
    passed (every path would pass them), partly opaque ones are kept (the path's first step
    passes them with probability ``1 - opacity``).
    """
    tri_v, tri_n, tri_uv, tri_mat, nodes_f, nodes_i, tri_front = geom
    mat_root, mat_flags, mat_emit, node_kind, nf, ni, tables, tex_data, tex_off, tex_w, tex_h, tex_uv = mats
    h, t, b1, b2 = closest_hit(o[0], o[1], o[2], d[0], d[1], d[2], np.inf, -1, tri_v, nodes_f, nodes_i,
                               stack_n, stack_t)
    travelled = 0.0
    for _layer in range(64):
        if h < 0 or (mat_flags[tri_mat[h]] & HAS_MASK) == 0:
            break
        p, ng, ns, tu, tv = surface(h, b1, b2, tri_v, tri_n, tri_uv)
        front = ns[0] * d[0] + ns[1] * d[1] + ns[2] * d[2] < 0.0
        if not transparent(mat_root[tri_mat[h]], front, tu, tv, node_kind, nf, ni, tex_data, tex_off,
                           tex_w, tex_h, tex_uv):
            break
        travelled += t
        h, t, b1, b2 = closest_hit(p[0], p[1], p[2], d[0], d[1], d[2], np.inf, h, tri_v, nodes_f,
                                   nodes_i, stack_n, stack_t)
    return h, b1, b2, t + travelled


@njit(parallel=True, cache=True, error_model="numpy")
def first_hits(eye, right, up, forward, tan_half, jx, jy, width, height, geom, mats, depth, threads):
    """Primary rays through the pixel centres (shifted by ``(jx, jy)``) of a pinhole camera and their
    first hits (:func:`first_hit`).

    Parameters
    ----------
    eye, right, up, forward : 3-tuples of float
        Camera position and basis (:meth:`harness.CameraPath.basis`).
    tan_half : float
        Tangent of half the vertical field of view.
    jx, jy : float
        Offset of every ray from its pixel's centre, pixels (x right, y down): the frame's jitter.
    width, height : int
    geom, mats, depth : scene arrays (see :class:`.scenedata.SceneData`).
    threads : int
        Workers taking tasks in turn (``numba.get_num_threads()``; see :func:`harness.kernels.take`).

    Returns
    -------
    origins, dirs : ndarray (N, 3) float64
        The rays, row-major pixel order.
    tri : ndarray (N,) int32
        Triangle hit, -1 for a miss.
    bary : ndarray (N, 3) float64
        Barycentric weights of corners 1 and 2, and the distance.
    """
    n = width * height
    origins = np.empty((n, 3))
    dirs = np.empty((n, 3))
    tri = np.empty(n, np.int32)
    bary = np.empty((n, 3))
    tasks = (n + TASK - 1) // TASK
    counter = np.zeros(1, np.int64)
    for _ in prange(min(max(threads, 1), tasks)):
        stack_n = np.empty(stack_size(depth), np.int32)
        stack_t = np.empty(stack_size(depth), np.float32)
        while True:
            task = kernels.take(counter)
            if task >= tasks:
                break
            for i in range(task * TASK, min(task * TASK + TASK, n)):
                o, d = pixel_ray(i, width, height, eye, right, up, forward, tan_half, jx, jy)
                origins[i, 0], origins[i, 1], origins[i, 2] = o
                dirs[i, 0], dirs[i, 1], dirs[i, 2] = d
                h, b1, b2, t = first_hit(o, d, geom, mats, stack_n, stack_t)
                tri[i] = h
                bary[i, 0] = b1
                bary[i, 1] = b2
                bary[i, 2] = t
    return origins, dirs, tri, bary


@njit(parallel=True, cache=True, error_model="numpy")
def accumulate_samples(origins, dirs, tri, bary, geom, mats, lights, lp, eps, depth, max_depth, rr_depth,
                       strategy, seed, frame, start, count, acc, acc_sq, acc_direct, shadow,
                       want_moments, want_split, threads):
    """Add ``count[p]`` samples, from sample index ``start[p]``, to pixel ``p``'s sums (in place).

    Parameters
    ----------
    origins, dirs : ndarray (N, 3) float64
        Primary rays (pixel centres), row-major pixel order.
    tri, bary : first hits from :func:`first_hits`.
    geom, mats, lights, lp, eps, depth : scene arrays (see :class:`.scenedata.SceneData`).
    max_depth, rr_depth, strategy : int
    seed, frame : int
    start : ndarray (N,) int64
    count : ndarray (N,) int64
    acc, acc_sq, acc_direct : ndarray (N, 3) float64
        Running sums of radiance, squared radiance and direct radiance.
    shadow : ndarray (N, 2) float64
        Running counts of first-hit light samples and of those that reached their light.
    want_moments, want_split : bool
        Whether to update ``acc_sq`` and ``acc_direct``.
    threads : int
        Workers taking tasks in turn (``numba.get_num_threads()``; see :func:`harness.kernels.take`).
    """
    n = origins.shape[0]
    emissive = any_emission(mats[2])
    tasks = (n + TASK - 1) // TASK
    counter = np.zeros(1, np.int64)
    for _ in prange(min(max(threads, 1), tasks)):
        stack_n = np.empty(stack_size(depth), np.int32)
        stack_t = np.empty(stack_size(depth), np.float32)
        while True:
            task = kernels.take(counter)
            if task >= tasks:
                break
            for i in range(task * TASK, min(task * TASK + TASK, n)):
                c = count[i]
                if c <= 0:
                    continue
                o = (origins[i, 0], origins[i, 1], origins[i, 2])
                d = (dirs[i, 0], dirs[i, 1], dirs[i, 2])
                s0, s1, s2 = acc[i, 0], acc[i, 1], acc[i, 2]
                q0 = q1 = q2 = d0 = d1 = d2 = 0.0
                if want_moments:  # untouched otherwise: no page of an unused sum is ever faulted in
                    q0, q1, q2 = acc_sq[i, 0], acc_sq[i, 1], acc_sq[i, 2]
                if want_split:
                    d0, d1, d2 = acc_direct[i, 0], acc_direct[i, 1], acc_direct[i, 2]
                rays = 0
                hits = 0
                for k in range(c):
                    key = stream_key(seed, frame, i, start[i] + k)
                    r, g, b, xr, xg, xb, vr, vh = trace_sample(key, o, d, tri[i], bary[i, 0], bary[i, 1], geom, mats,
                                                               lights, lp, eps, max_depth, rr_depth, strategy,
                                                               emissive, stack_n, stack_t)
                    if not (math.isfinite(r) and math.isfinite(g) and math.isfinite(b)
                            and math.isfinite(xr) and math.isfinite(xg) and math.isfinite(xb)):
                        r = g = b = xr = xg = xb = 0.0
                    s0 += r
                    s1 += g
                    s2 += b
                    if want_moments:
                        q0 += r * r
                        q1 += g * g
                        q2 += b * b
                    if want_split:
                        d0 += xr
                        d1 += xg
                        d2 += xb
                    rays += vr
                    hits += vh
                acc[i, 0], acc[i, 1], acc[i, 2] = s0, s1, s2
                if want_moments:
                    acc_sq[i, 0], acc_sq[i, 1], acc_sq[i, 2] = q0, q1, q2
                if want_split:
                    acc_direct[i, 0], acc_direct[i, 1], acc_direct[i, 2] = d0, d1, d2
                shadow[i, 0] += rays
                shadow[i, 1] += hits


@njit(parallel=True, cache=True, error_model="numpy")
def accumulate_area(eye, right, up, forward, tan_half, width, height, geom, mats, lights, lp, eps, depth, max_depth,
                    rr_depth, strategy, seed, frame, start, count, acc, threads):
    """Add ``count[p]`` pixel-area samples, from sample index ``start[p]``, to pixel ``p``'s sum (in place).

    Each sample's camera ray goes through its own point of the pixel (:func:`.pixel_sampling.subpixel`)
    and is traced to its own first hit (:func:`first_hit`) before the path continues as in
    :func:`accumulate_samples`; the sums are the same whatever the thread count or the split of
    the samples into calls.

    Parameters
    ----------
    eye, right, up, forward, tan_half, width, height : the camera, as for :func:`first_hits`.
    geom, mats, lights, lp, eps, depth : scene arrays (see :class:`.scenedata.SceneData`).
    max_depth, rr_depth, strategy, seed, frame : int
    start, count : ndarray (N,) int64
    acc : ndarray (N, 3) float64
        Running sums of radiance.
    threads : int
    """
    n = width * height
    emissive = any_emission(mats[2])
    tasks = (n + TASK - 1) // TASK
    counter = np.zeros(1, np.int64)
    for _ in prange(min(max(threads, 1), tasks)):
        stack_n = np.empty(stack_size(depth), np.int32)
        stack_t = np.empty(stack_size(depth), np.float32)
        while True:
            task = kernels.take(counter)
            if task >= tasks:
                break
            for i in range(task * TASK, min(task * TASK + TASK, n)):
                s0, s1, s2 = acc[i, 0], acc[i, 1], acc[i, 2]
                for k in range(count[i]):
                    sample = start[i] + k
                    jx, jy = subpixel(seed, frame, i, sample)
                    o, d = pixel_ray(i, width, height, eye, right, up, forward, tan_half, jx, jy)
                    h, b1, b2, _t = first_hit(o, d, geom, mats, stack_n, stack_t)
                    key = stream_key(seed, frame, i, sample)
                    r, g, b, _xr, _xg, _xb, _vr, _vh = trace_sample(key, o, d, h, b1, b2, geom, mats, lights, lp, eps,
                                                                    max_depth, rr_depth, strategy, emissive, stack_n,
                                                                    stack_t)
                    if math.isfinite(r) and math.isfinite(g) and math.isfinite(b):
                        s0 += r
                        s1 += g
                        s2 += b
                acc[i, 0], acc[i, 1], acc[i, 2] = s0, s1, s2

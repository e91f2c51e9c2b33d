"""Samples and first hits with Mitsuba's JIT variants (``llvm_ad_rgb``, ``cuda_ad_rgb``), vectorized.

Each lane is one sample of one pixel: its primary ray goes through the pixel centre (as in the
path tracer, so every sample starts at the G-buffer's first hit), and Mitsuba's ``path``
integrator traces the rest with the lane's own stream (:mod:`.streams`). The first hits of the
G-buffer come from ``Scene.ray_intersect`` on the same rays. No Python code runs per pixel.
"""

from __future__ import annotations

import numpy as np

from .camera import sensor
from .streams import lane_keys, stream_sampler


def primary_rays(mi, camera, pixels, width: int, height: int, offset=None):
    """Rays of sensor ``camera`` through row-major ``pixels`` (mitsuba.UInt32) of a ``width`` x
    ``height`` film: through their centres, or through ``offset`` (mitsuba.Point2f in [0, 1)^2, per
    lane) inside them."""
    dx, dy = (0.5, 0.5) if offset is None else (offset.x, offset.y)
    x = (mi.Float(pixels % width) + dx) / width
    y = (mi.Float(pixels // width) + dy) / height
    ray, _ = camera.sample_ray(0.0, 0.5, mi.Point2f(x, y), mi.Point2f(0.5, 0.5))
    return ray


class JitEngine:
    """Renders lanes of (pixel, sample) with a JIT variant.

    Parameters
    ----------
    mi : module
        ``mitsuba`` with the variant set (the caller keeps it set while calling).
    mi_scene : mitsuba.Scene
    integrator : mitsuba.Integrator
        A sampling integrator (``path``).
    shape_ids : dict of str to int
        Object id of each shape id (:func:`.shapes.object_ids`).
    """

    #: lanes per wavefront on the CPU (the LLVM backend), and on a GPU
    LANES = {"llvm": 1 << 20, "cuda": 1 << 23}

    def __init__(self, mi, mi_scene, integrator, shape_ids: dict[str, int]):
        import drjit as dr

        self.mi, self.dr, self.scene, self.integrator = mi, dr, mi_scene, integrator
        self.max_lanes = self.LANES["cuda" if mi.variant().startswith("cuda") else "llvm"]
        self._sampler = stream_sampler(mi)
        shapes = mi_scene.shapes()
        registry = [int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(s))[0]) for s in shapes]
        self._ids = np.full(max(registry, default=0) + 1, -1, np.int32)
        for shape, index in zip(shapes, registry):
            self._ids[index] = shape_ids[shape.id()]

    def radiance(self, view: dict, pixels: np.ndarray, samples: np.ndarray, base: int,
                 area: bool = False) -> np.ndarray:
        """Radiance of one sample per lane, (n, 3) float32 (non-finite samples become 0).

        Parameters
        ----------
        view : dict
            :func:`.camera.view` of the frame.
        pixels, samples : ndarray (n,) integer
            Row-major pixel and sample index of each lane (n <= :attr:`max_lanes`).
        base : int
            :func:`.streams.base_key` of the seed, frame and purpose.
        area : bool
            The primary ray goes through a point uniform in the pixel (the lane's first two random
            numbers; references integrate over the pixel area, box filter) instead of its centre.
        """
        mi = self.mi
        p = mi.UInt32(np.ascontiguousarray(pixels, np.uint32))
        s = mi.UInt32(np.ascontiguousarray(samples, np.uint32))
        state, sequence = lane_keys(mi, base, p, s)
        self._sampler.start(state, sequence)
        offset = self._sampler.next_2d() if area else None
        ray = primary_rays(mi, sensor(mi, view), p, view["width"], view["height"], offset)
        color, _, _ = self.integrator.sample(self.scene, self._sampler, ray, None, True)
        out = np.array(color, np.float32).reshape(3, -1).T.copy()
        out[~np.isfinite(out).all(axis=1)] = 0.0
        return out

    def first_hits(self, view: dict) -> dict:
        """Row-major arrays of the pixel-centre rays' first hits: ``hit`` (bool), ``position``,
        ``normal``, ``albedo``, ``emission`` ((n, 3) float64) and ``object_id`` (int32); see
        :mod:`.gbuffer` for what becomes of them."""
        mi, dr = self.mi, self.dr
        width, height = view["width"], view["height"]
        ray = primary_rays(mi, sensor(mi, view), dr.arange(mi.UInt32, width * height), width, height)
        si = self.scene.ray_intersect(ray)
        hit = si.is_valid()
        normal = si.sh_frame.n
        normal = dr.select(dr.dot(si.n, ray.d) > 0.0, -normal, normal)
        bsdf = si.bsdf(ray)
        diffuse = mi.has_flag(bsdf.flags(), mi.BSDFFlags.Diffuse)
        albedo = bsdf.eval_diffuse_reflectance(si, hit & diffuse)
        # no diffuse lobe: the weight of the specular lobe sampled at normal incidence
        # (F0 times the specular reflectance of a conductor, white for glass)
        front = mi.SurfaceInteraction3f(si)
        front.wi = mi.Vector3f(0.0, 0.0, 1.0)
        _, weight = bsdf.sample(mi.BSDFContext(), front, 0.0, mi.Point2f(0.5, 0.5), hit & ~diffuse)
        albedo = dr.select(diffuse, albedo, weight)
        emission = si.emitter(self.scene).eval(si, hit)
        shape = dr.reinterpret_array(mi.UInt32, si.shape)
        dr.eval(hit, si.p, normal, albedo, emission, shape)
        hit = np.array(hit, bool)
        position = _vec(si.p)
        shape_index = np.array(shape, np.int64)
        known = hit & (shape_index < len(self._ids))
        object_id = np.where(known, self._ids[np.where(known, shape_index, 0)], -1)
        return {
            "hit": hit,
            "position": position,
            "normal": _vec(normal),
            "albedo": _vec(albedo),
            "emission": _vec(emission),
            "object_id": object_id.astype(np.int32),
        }


def _vec(value) -> np.ndarray:
    """A Mitsuba 3-vector/colour array as (n, 3) float64."""
    return np.array(value, np.float64).reshape(3, -1).T.copy()

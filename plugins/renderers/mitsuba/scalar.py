"""Samples and first hits with ``scalar_rgb``: the fallback where no LLVM works.

The scalar variant has no vectorized Python API, so it renders whole images with ``mi.render``
(C++ threads, no Python per pixel): one image of one sample per pixel per sample index
(``seed`` from :func:`.streams.image_seed`), through a film with a box filter, so each pixel's
value is one sample of it. Two differences from the JIT variants follow, and are documented:
Mitsuba places each sample's primary ray uniformly inside its pixel (not through its centre),
and a lane set that needs only some pixels of a sample index still renders the whole image.
The G-buffer comes from the ``aov`` integrator through a sampler that puts the one sample of each
pixel at its centre (``stratified``, no jitter), and the emission from ``path`` with
``max_depth`` 1 through the same centres; the albedo is Mitsuba's diffuse reflectance only
(zero on conductors and glass, which the JIT variants give their specular weight).
"""

from __future__ import annotations

import numpy as np

from .camera import sensor
from .streams import image_seed

#: the AOVs of the G-buffer, in the order of the image's channels
AOVS = "p:position,n:sh_normal,g:geo_normal,a:albedo,t:depth,s:shape_index"


class ScalarEngine:
    """Renders lanes of (pixel, sample) with ``scalar_rgb`` (see the module's notes).

    Parameters
    ----------
    mi : module
        ``mitsuba`` with ``scalar_rgb`` set.
    mi_scene : mitsuba.Scene
    integrator : mitsuba.Integrator
    shape_ids : dict of str to int
        Object id of each shape id.
    """

    #: lanes per call (each call renders the images of the sample indices it holds)
    max_lanes = 1 << 22

    def __init__(self, mi, mi_scene, integrator, shape_ids: dict[str, int]):
        self.mi, self.scene, self.integrator = mi, mi_scene, integrator
        self._shape_ids = shape_ids
        self._aov = mi.load_dict({"type": "aov", "aovs": AOVS})
        self._emitted = mi.load_dict({"type": "path", "max_depth": 1})

    def radiance(self, view: dict, pixels: np.ndarray, samples: np.ndarray, base: int,
                 area: bool = True) -> np.ndarray:
        """Radiance of one sample per lane, (n, 3) float32: one ``mi.render`` per distinct sample index
        (its primary rays are uniform in the pixel whatever ``area`` says)."""
        camera = sensor(self.mi, view)
        out = np.zeros((len(pixels), 3), np.float32)
        for s in np.unique(samples):
            lanes = np.flatnonzero(samples == s)
            image = np.array(self.mi.render(self.scene, sensor=camera, integrator=self.integrator, spp=1,
                                            seed=image_seed(base, int(s))), np.float32)
            out[lanes] = image[..., :3].reshape(-1, 3)[pixels[lanes]]
        out[~np.isfinite(out).all(axis=1)] = 0.0
        return out

    def first_hits(self, view: dict) -> dict:
        """G-buffer arrays of the pixel centres: hit, position, normal, albedo, emission, object_id."""
        mi = self.mi
        centres = sensor(mi, view, {"type": "stratified", "sample_count": 1, "jitter": False})
        aov = np.array(mi.render(self.scene, sensor=centres, integrator=self._aov, spp=1), np.float64)
        emitted = np.array(mi.render(self.scene, sensor=centres, integrator=self._emitted, spp=1), np.float64)
        n = view["width"] * view["height"]
        aov = aov.reshape(n, -1)
        position, normal, geometric, albedo = aov[:, 0:3], aov[:, 3:6], aov[:, 6:9], aov[:, 9:12]
        hit = aov[:, 12] > 0.0
        view_dir = position - np.asarray(view["eye"], np.float64)
        back = np.einsum("ij,ij->i", geometric, view_dir) > 0.0
        normal = np.where(back[:, None], -normal, normal)
        return {
            "hit": hit,
            "position": position,
            "normal": normal,
            "albedo": albedo,
            "emission": emitted.reshape(n, -1)[:, :3],
            "object_id": self._object_ids(centres, view, aov[:, 13], hit),
        }

    def _object_ids(self, centres, view: dict, index: np.ndarray, hit: np.ndarray) -> np.ndarray:
        """Object ids from the ``shape_index`` AOV: one centre ray per distinct value names its shape."""
        mi = self.mi
        width, height = view["width"], view["height"]
        out = np.full(index.shape, -1, np.int32)
        for value in np.unique(index[hit]):
            pixels = np.flatnonzero(hit & (index == value))
            i, j = divmod(int(pixels[0]), width)
            ray, _ = centres.sample_ray(0.0, 0.5, mi.Point2f((j + 0.5) / width, (i + 0.5) / height),
                                       mi.Point2f(0.5, 0.5))
            si = self.scene.ray_intersect(ray)
            if si.shape is not None:
                out[pixels] = self._shape_ids.get(si.shape.id(), -1)
        return out

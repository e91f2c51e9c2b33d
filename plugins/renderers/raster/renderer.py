"""The ``raster`` renderer: G-buffers and cheap rasterized colour for mesh scenes."""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from math import isqrt

import numpy as np

from harness import Frame, FrameMeta, halton_jitter

from .attributes import TextureTable, surface_kernel
from .motion import motion_vectors
from .shading import environment_image, shade, specular_table
from .visibility import VisibilityRasterizer

PROVIDES = frozenset({"color", "albedo", "normal", "depth", "position", "object_id", "motion"})
MAX_REFERENCE_SUPERSAMPLE = 16


@dataclass
class GBuffer:
    """First-hit surface values of one rasterized image (background: tri = -1)."""

    tri: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    uv: np.ndarray
    depth: np.ndarray
    material: np.ndarray
    object_id: np.ndarray
    direction: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        return self.tri >= 0


class RasterRenderer:
    """Rasterized G-buffer and local shading of :class:`harness.Scene` meshes.

    Parameters
    ----------
    supersample : int
        ``s``: the ``color`` channel of :meth:`render` averages an ``s x s`` grid of sub-pixel
        samples (box filter); G-buffer channels always come from the (jittered) pixel centre.
    jitter : bool
        Offset the projection of frame ``t`` by the Halton (2, 3) point ``(t mod 16) + 1``
        (minus 0.5), as engines do for temporal anti-aliasing; the offset is in
        ``FrameMeta.jitter``. On by default: the renderer serves the anti-aliasing task, whose
        filters (TAA, ``aa_rnn``) expect jittered frames; ``jitter=False`` renders pixel centres.
    """

    def __init__(self, supersample: int = 1, jitter: bool = True):
        if int(supersample) < 1:
            raise ValueError(f"raster: supersample must be >= 1, got {supersample}")
        self.supersample = int(supersample)
        self.jitter = bool(jitter)
        self._rasterizer: VisibilityRasterizer | None = None
        self._soups: OrderedDict = OrderedDict()
        self._tables: OrderedDict = OrderedDict()

    def settings(self) -> dict:
        """The options that change images (part of cache keys)."""
        return {"supersample": self.supersample, "jitter": self.jitter}

    # ------------------------------------------------------------------ caches

    def _soup(self, scene, frame: int):
        key = (scene.content_hash(), frame)
        if key not in self._soups:
            self._soups[key] = scene.triangles(frame)
            while len(self._soups) > 2:
                self._soups.popitem(last=False)
        return self._soups[key]

    def _table(self, scene):
        key = scene.content_hash()
        if key not in self._tables:
            env = scene.environment
            self._tables[key] = (TextureTable(scene.materials),
                                 np.array([m.emission for m in scene.materials] or [[0.0] * 3], np.float32),
                                 environment_image(env), specular_table(scene.materials))
            while len(self._tables) > 1:
                self._tables.popitem(last=False)
        return self._tables[key]

    # ------------------------------------------------------------------ passes

    def gbuffer(self, scene, frame: int, width: int, height: int, jitter=(0.0, 0.0)) -> GBuffer:
        """Rasterize ``frame`` of ``scene`` and compute exact first-hit attributes.

        Parameters
        ----------
        scene : harness.Scene
        frame : int
        width, height : int
        jitter : (float, float)
            Sub-pixel offset in pixels (x right, y down), as in :meth:`harness.CameraPath.primary_rays`.
        """
        if scene.camera is None:
            raise ValueError(f"raster: scene {scene.name!r} has no camera")
        soup = self._soup(scene, frame)
        camera = scene.camera
        if self._rasterizer is None:
            self._rasterizer = VisibilityRasterizer()
        view_proj = _raster_view_proj(camera, frame, width, height, jitter, soup)
        tri = self._rasterizer.triangle_ids(soup.vertices, view_proj, width, height)
        position = np.zeros((height, width, 3), np.float32)
        normal = np.zeros((height, width, 3), np.float32)
        uv = np.zeros((height, width, 2), np.float32)
        depth = np.full((height, width), np.inf, np.float32)
        direction = np.zeros((height, width, 3), np.float32)
        right, up, forward = camera.basis(frame)
        surface_kernel(tri, soup.vertices.astype(np.float64), soup.normals.astype(np.float64),
                       soup.uvs.astype(np.float64), camera.eye(frame), right, up, forward,
                       float(np.tan(np.radians(camera.fov_at(frame)) / 2.0)), float(jitter[0]), float(jitter[1]),
                       position, normal, uv, depth, direction)
        hit = tri >= 0
        material = np.full((height, width), -1, np.int32)
        object_id = np.full((height, width), -1, np.int32)
        material[hit] = soup.material[tri[hit]]
        object_id[hit] = soup.object_id[tri[hit]]
        return GBuffer(tri, position, normal, uv, depth, material, object_id, direction)

    def _color(self, scene, frame: int, width: int, height: int, jitter, s: int, g: GBuffer | None = None,
               albedo: np.ndarray | None = None) -> np.ndarray:
        """Shaded colour averaged over an ``s x s`` sub-pixel grid around the jittered pixel centres.

        ``g`` and ``albedo`` may pass the pixel-centre G-buffer already computed when ``s == 1``.
        """
        table, emission_table, env_image, specular = self._table(scene)
        big_w, big_h = width * s, height * s
        # sub-pixel (a, b) of pixel (i, j) is big pixel (i*s + b, j*s + a): its centre sits at
        # ((a + 0.5) / s - 0.5) pixels from the small pixel's centre
        big_jitter = (jitter[0] * s, jitter[1] * s)
        if g is None:
            g = self.gbuffer(scene, frame, big_w, big_h, big_jitter)
        if albedo is None:
            albedo = table.albedo(g.material, g.uv)
        color = shade(scene, g.material, albedo, g.normal, g.direction, emission_table, specular, env_image)
        if s == 1:
            return color
        return color.reshape(height, s, width, s, 3).mean(axis=(1, 3), dtype=np.float64).astype(np.float32)

    # ------------------------------------------------------------------ protocol

    def render(self, scene, frame_index: int, *, spp: int = 1, seed: int = 0, channels=frozenset(),
               resolution=None) -> Frame:
        """Render the requested channels (plus ``color``) of one frame.

        ``spp`` and ``seed`` do not change the image (rasterization is deterministic); they are
        kept in the frame's metadata.
        """
        channels = frozenset(channels) | {"color"}
        unknown = sorted(channels - PROVIDES)
        if unknown:
            raise ValueError(f"raster: cannot provide channel(s) {unknown}; it provides {sorted(PROVIDES)}")
        width, height = resolution or scene.resolution
        jitter = halton_jitter(frame_index) if self.jitter else (0.0, 0.0)
        out = {}
        g = albedo = None
        if channels - {"color"} or self.supersample == 1:
            g = self.gbuffer(scene, frame_index, width, height, jitter)
            table = self._table(scene)[0]
            albedo = table.albedo(g.material, g.uv)
            if "albedo" in channels:
                out["albedo"] = albedo
            for name in ("normal", "depth", "position", "object_id"):
                if name in channels:
                    out[name] = getattr(g, name)
            if "motion" in channels:
                out["motion"] = motion_vectors(scene, g.position, g.object_id, frame_index)
        if self.supersample == 1:
            out["color"] = self._color(scene, frame_index, width, height, jitter, 1, g, albedo)
        else:
            out["color"] = self._color(scene, frame_index, width, height, jitter, self.supersample)
        camera = scene.camera
        view_proj = camera.view_projection(frame_index, width, height, jitter)
        if frame_index > 0:
            prev_jitter = halton_jitter(frame_index - 1) if self.jitter else (0.0, 0.0)
            prev_view_proj = camera.view_projection(frame_index - 1, width, height, prev_jitter)
        else:
            prev_view_proj = view_proj
        meta = FrameMeta(index=frame_index, scene=scene.name, seed=seed, view_proj=view_proj,
                         prev_view_proj=prev_view_proj, jitter=tuple(jitter), camera_cut=frame_index == 0,
                         extra={"max_depth": scene.max_depth, "spp": spp, "supersample": self.supersample})
        return Frame(out, meta, owner="raster")

    def reference(self, scene, frame_index: int, *, spp: int = 64, seed: int = 0, resolution=None) -> np.ndarray:
        """The same shading as :meth:`render`'s colour, box-filtered over ``s x s`` unjittered samples.

        ``s = clamp(isqrt(spp), 1, 16)``: the default ``spp = 64`` gives the 8 x 8 supersampled
        (SSAA) reference of the anti-aliasing task. The ``s W x s H`` image is rendered whole
        (about 100 bytes a sample: 16 x 16 at 320 x 180 peaks near 3.5 GB).
        """
        width, height = resolution or scene.resolution
        s = min(max(isqrt(max(int(spp), 1)), 1), MAX_REFERENCE_SUPERSAMPLE)
        return self._color(scene, frame_index, width, height, (0.0, 0.0), s)


def _raster_view_proj(camera, frame: int, width: int, height: int, jitter, soup) -> np.ndarray:
    """World-to-clip matrix of ``camera`` with the far plane pulled in to the scene's extent.

    Only the depth mapping differs from :meth:`harness.CameraPath.view_projection`, so pixel
    coverage is the same while the depth buffer resolves surfaces better.
    """
    view = camera.view_matrix(frame)
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    lo = soup.vertices.reshape(-1, 3).min(axis=0) if len(soup.vertices) else np.zeros(3)
    hi = soup.vertices.reshape(-1, 3).max(axis=0) if len(soup.vertices) else np.ones(3)
    box = lo + corners * (hi - lo)
    extent = float(np.max(-(box @ view[:3, :3].T + view[:3, 3])[:, 2]))
    near = camera.near
    far = min(camera.far, max(extent * 1.01 + near, 2.0 * near))
    proj = camera.projection_matrix(width, height, jitter, frame)
    proj[2, 2] = (far + near) / (near - far)
    proj[2, 3] = 2.0 * far * near / (near - far)
    return proj @ view

"""The ``pathtracer`` renderer object: the harness's renderer protocol over the Numba kernels."""

from __future__ import annotations

from collections import OrderedDict

import numba
import numpy as np

from harness import Frame, FrameMeta, Scene, StreamRenderer, halton_jitter

from .gbuffer import gbuffer
from .integrator import STRATEGIES, accumulate_area, accumulate_samples, first_hits
from .materials import ONE_SIDED_EMISSION
from .pixel_sampling import REFERENCE_PIXELS
from .pixels import PixelState
from .scenedata import SceneData, build_scene_data

OWNER = "renderer 'pathtracer'"
GBUFFER_CHANNELS = ("albedo", "normal", "depth", "position", "object_id", "motion", "emission", "visibility")


def camera_arguments(scene: Scene, frame_index: int) -> tuple:
    """``(eye, right, up, forward, tan_half)`` of the scene's camera in a frame, as the kernels take them."""
    if scene.camera is None:
        raise ValueError(f"{OWNER}: scene {scene.name!r} has no camera")
    cam = scene.camera
    right, up, forward = (tuple(float(x) for x in v) for v in cam.basis(frame_index))
    eye = tuple(float(x) for x in cam.eye(frame_index))
    return eye, right, up, forward, float(np.tan(np.radians(cam.fov_at(frame_index)) / 2.0))


class FrameSetup:
    """Everything about one (scene, frame, resolution, jitter) that does not depend on samples.

    ``jitter``: the offset (x right, y down, pixels) of every pixel's first hit from its centre.
    """

    def __init__(self, scene: Scene, frame_index: int, width: int, height: int, data: SceneData,
                 jitter=(0.0, 0.0)):
        self.scene, self.index, self.width, self.height, self.data = scene, frame_index, width, height, data
        self.jitter = (float(jitter[0]), float(jitter[1]))
        eye, right, up, forward, tan_half = camera_arguments(scene, frame_index)
        self.origins, self.dirs, self.tri, self.bary = first_hits(eye, right, up, forward, tan_half, *self.jitter,
                                                                  width, height, data.geometry(), data.materials(),
                                                                  data.depth, numba.get_num_threads())
        self._gbuffer = None

    def gbuffer(self) -> dict:
        """G-buffer arrays (H, W, ...) of the first hits, computed once."""
        if self._gbuffer is None:
            h, w = self.height, self.width
            forward = np.asarray(self.scene.camera.basis(self.index)[2], np.float64)
            pos, nrm, alb, depth, oid = gbuffer(self.origins, self.dirs, self.tri, self.bary, forward,
                                                self.data.geometry(), self.data.materials(), self.data.tri_obj,
                                                self.data.mats.gbuffer_albedo, self.data.mats.gbuffer_tex)
            self._gbuffer = {
                "position": pos.reshape(h, w, 3),
                "normal": nrm.reshape(h, w, 3),
                "albedo": alb.reshape(h, w, 3),
                "depth": depth.reshape(h, w),
                "object_id": oid.reshape(h, w),
                "emission": self.emission().reshape(h, w, 3),
            }
        return self._gbuffer

    def emission(self) -> np.ndarray:
        """Emitted radiance of each pixel's first hit (N, 3) float32; zero for background.

        As in the integrator, both faces of an emitter emit, but one-sided emitters (Mitsuba's
        ``area``) only on their front, so this is exactly the part of ``color`` that reaches the
        camera without a bounce.
        """
        data = self.data
        mat_emit = np.asarray(data.mat_emit, np.float32)
        tri_mat = np.asarray(data.tri_mat)
        hit = np.flatnonzero(self.tri >= 0)
        t = self.tri[hit]
        out = np.zeros((self.tri.shape[0], 3), np.float32)
        v = data.tri_v[t].astype(np.float64).reshape(-1, 3, 3)
        facing = np.einsum("ij,ij->i", np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), -self.dirs[hit])
        one_sided = (data.mats.mat_flags[tri_mat[t]] & ONE_SIDED_EMISSION) != 0
        lit = ~one_sided | (data.tri_front[t] * facing > 0.0)
        out[hit[lit]] = mat_emit[tri_mat[t[lit]]]
        return out


class PathTracer(StreamRenderer):
    """Numba CPU path tracer of ``mesh`` scenes.

    Parameters
    ----------
    max_depth : int or None
        Longest path in segments (1: emitters seen directly, 2: direct lighting); None uses the
        scene's ``max_depth``.
    rr_depth : int
        Bounce from which Russian roulette may end paths.
    strategy : {"mis", "light", "bsdf"}
        Next-event estimation with MIS (default), light sampling only, or BSDF sampling only.
    jitter : bool
        Noisy frames (and their G-buffer) through the pixel centres shifted by the frame's Halton
        (2, 3) offset, as TAA engines render; False (default): through the pixel centres, as a
        rasterized G-buffer without jitter (see :mod:`.pixel_sampling`).
    reference_pixel : {"area", "centre"}
        References integrate over the pixel area (box filter, stratified; default, as Mitsuba 3)
        or take the pixel centre.
    """

    owner = OWNER
    pixel_state = PixelState

    def __init__(self, max_depth: int | None = None, rr_depth: int = 5, strategy: str = "mis", jitter: bool = False,
                 reference_pixel: str = "area"):
        if strategy not in STRATEGIES:
            raise ValueError(f"{OWNER}: strategy must be one of {sorted(STRATEGIES)}, got {strategy!r}")
        if max_depth is not None and int(max_depth) < 1:
            raise ValueError(f"{OWNER}: max_depth must be >= 1, got {max_depth}")
        if int(rr_depth) < 1:
            raise ValueError(f"{OWNER}: rr_depth must be >= 1, got {rr_depth}")
        if not isinstance(jitter, bool):
            raise ValueError(f"{OWNER}: jitter must be true or false, got {jitter!r}")
        if reference_pixel not in REFERENCE_PIXELS:
            raise ValueError(f"{OWNER}: reference_pixel must be one of {list(REFERENCE_PIXELS)}, "
                             f"got {reference_pixel!r}")
        self.max_depth = None if max_depth is None else int(max_depth)
        self.rr_depth = int(rr_depth)
        self.strategy = strategy
        self.jitter = jitter
        self.reference_pixel = reference_pixel
        self._scenes: OrderedDict = OrderedDict()
        self._setups: OrderedDict = OrderedDict()

    def settings(self) -> dict:
        """Settings that change images (part of cache keys), the sampling conventions included."""
        return {"max_depth": self.max_depth, "rr_depth": self.rr_depth, "strategy": self.strategy,
                "jitter": self.jitter, "reference_pixel": self.reference_pixel}

    def frame_jitter(self, frame_index: int) -> tuple[float, float]:
        """The offset of a noisy frame's first hits from the pixel centres (zero without ``jitter``)."""
        return halton_jitter(frame_index) if self.jitter else (0.0, 0.0)

    # -- preparation ---------------------------------------------------------------------------
    def scene_data(self, scene: Scene, frame_index: int) -> SceneData:
        """Scene arrays and BVH for a frame (static scenes share one build)."""
        if scene.kind != "mesh":
            raise ValueError(f"{OWNER}: renders mesh scenes only; {scene.name!r} is {scene.kind!r}")
        animated = any(o.transforms is not None and np.asarray(o.transforms).ndim == 3 for o in scene.objects)
        key = (scene.content_hash(), frame_index if animated else 0)
        if key not in self._scenes:
            self._scenes[key] = build_scene_data(scene, frame_index)
            while len(self._scenes) > 2:
                self._scenes.popitem(last=False)
        self._scenes.move_to_end(key)
        return self._scenes[key]

    def setup(self, scene: Scene, frame_index: int, resolution=None, jitter=None) -> FrameSetup:
        """Primary rays and first hits of a frame at a resolution (cached); ``jitter`` None: the noisy
        frames' convention (:meth:`frame_jitter`)."""
        w, h = (int(v) for v in (resolution or scene.resolution))
        if w < 1 or h < 1:
            raise ValueError(f"{OWNER}: resolution must be positive, got {(w, h)}")
        jitter = self.frame_jitter(frame_index) if jitter is None else (float(jitter[0]), float(jitter[1]))
        key = (scene.content_hash(), frame_index, w, h, jitter)
        if key not in self._setups:
            self._setups[key] = FrameSetup(scene, frame_index, w, h, self.scene_data(scene, frame_index), jitter)
            while len(self._setups) > 2:
                self._setups.popitem(last=False)
        self._setups.move_to_end(key)
        return self._setups[key]

    def _max_depth(self, scene: Scene) -> int:
        return self.max_depth if self.max_depth is not None else max(int(scene.max_depth), 1)

    def add_samples(self, setup: FrameSetup, state: PixelState, counts: np.ndarray, seed: int, *,
                    moments: bool = True, split: bool = True) -> None:
        """Take ``counts[p]`` more samples in pixel ``p``, continuing its stream (in place)."""
        counts = np.ascontiguousarray(counts, np.int64).ravel()
        data = setup.data
        accumulate_samples(setup.origins, setup.dirs, setup.tri, setup.bary, data.geometry(), data.materials(),
                           data.lights(), data.lp, data.eps, data.depth, self._max_depth(setup.scene), self.rr_depth,
                           STRATEGIES[self.strategy], int(seed), int(setup.index), state.spp, counts, state.acc,
                           state.acc_sq, state.acc_direct, state.shadow, moments, split, numba.get_num_threads())
        state.spp += counts

    # -- frames --------------------------------------------------------------------------------
    def frame(self, setup: FrameSetup, state: PixelState, seed: int, channels) -> Frame:
        """Assemble a :class:`harness.Frame` with ``channels`` (and ``color``) from running sums."""
        h, w = setup.height, setup.width
        n = np.maximum(state.spp, 1)[:, None].astype(np.float64)
        mean = state.acc / n
        out = {"color": mean.reshape(h, w, 3).astype(np.float32)}
        if "direct" in channels or "indirect" in channels:
            direct = state.acc_direct / n
            out["direct"] = direct.reshape(h, w, 3).astype(np.float32)
            out["indirect"] = (mean - direct).reshape(h, w, 3).astype(np.float32)
        if "variance" in channels:
            k = state.spp[:, None].astype(np.float64)
            var = np.maximum(state.acc_sq - k * mean * mean, 0.0) / np.maximum(k * (k - 1.0), 1.0)
            var[state.spp < 2] = 0.0
            out["variance"] = var.reshape(h, w, 3).astype(np.float32)
        if "spp" in channels:
            out["spp"] = state.spp.reshape(h, w).astype(np.int32)
        if "visibility" in channels:
            vis = state.shadow[:, 1] / np.maximum(state.shadow[:, 0], 1.0)
            out["visibility"] = vis.reshape(h, w).astype(np.float32)
        wanted = [c for c in GBUFFER_CHANNELS if c in channels and c != "visibility"]
        if wanted:
            g = setup.gbuffer()
            for name in wanted:
                if name == "motion":
                    out[name] = setup.scene.motion(g["position"], g["object_id"], setup.index, w, h)
                else:
                    out[name] = g[name]
        out = {k: v for k, v in out.items() if k == "color" or k in channels}
        cam = setup.scene.camera
        previous = max(setup.index - 1, 0)
        meta = FrameMeta(
            index=setup.index,
            scene=setup.scene.name,
            seed=int(seed),
            view_proj=cam.view_projection(setup.index, w, h, setup.jitter),
            prev_view_proj=cam.view_projection(previous, w, h, self.frame_jitter(previous)),
            jitter=setup.jitter,
            camera_cut=setup.index == 0,
            extra={"max_depth": self._max_depth(setup.scene), "samples": int(state.spp.sum())},
        )
        return Frame(out, meta, owner=OWNER)

    def render(self, scene: Scene, frame_index: int, *, spp: int = 1, seed: int = 0, channels=frozenset(),
               resolution=None) -> Frame:
        """A frame of ``spp`` samples per pixel with the requested channels (``color`` always).

        Parameters
        ----------
        scene : harness.Scene
        frame_index : int
        spp : int
            Samples per pixel, >= 1.
        seed : int
        channels : iterable of str
        resolution : (int, int) or None
            (width, height); None uses the scene's.
        """
        if int(spp) < 1:
            raise ValueError(f"{OWNER}: spp must be >= 1, got {spp}")
        channels = frozenset(channels)
        setup = self.setup(scene, frame_index, resolution)
        state = PixelState(setup.width * setup.height)
        self.add_samples(setup, state, np.full(state.spp.shape, int(spp), np.int64), seed,
                         moments="variance" in channels,
                         split="direct" in channels or "indirect" in channels)
        return self.frame(setup, state, seed, channels)

    def accumulate(self, scene: Scene, frame_index: int, *, first_sample: int, count: int, seed: int = 0,
                   resolution=None) -> np.ndarray:
        """Sum of the radiance of samples ``[first_sample, first_sample + count)`` per pixel, over the
        pixel's area (``reference_pixel="area"``) or at its centre.

        Returns
        -------
        ndarray (H, W, 3) float64
        """
        if int(first_sample) < 0 or int(count) < 0:
            raise ValueError(f"{OWNER}: first_sample and count must be >= 0, got {first_sample}, {count}")
        if self.reference_pixel == "centre":
            setup = self.setup(scene, frame_index, resolution, jitter=(0.0, 0.0))
            state = PixelState(setup.width * setup.height)
            state.spp[:] = int(first_sample)
            self.add_samples(setup, state, np.full(state.spp.shape, int(count), np.int64), seed,
                             moments=False, split=False)
            return state.acc.reshape(setup.height, setup.width, 3)
        w, h = (int(v) for v in (resolution or scene.resolution))
        if w < 1 or h < 1:
            raise ValueError(f"{OWNER}: resolution must be positive, got {(w, h)}")
        data = self.scene_data(scene, frame_index)
        acc = np.zeros((w * h, 3))
        accumulate_area(*camera_arguments(scene, frame_index), w, h, data.geometry(), data.materials(), data.lights(),
                        data.lp, data.eps, data.depth, self._max_depth(scene), self.rr_depth,
                        STRATEGIES[self.strategy], int(seed), int(frame_index),
                        np.full(w * h, int(first_sample), np.int64), np.full(w * h, int(count), np.int64), acc,
                        numba.get_num_threads())
        return acc.reshape(h, w, 3)

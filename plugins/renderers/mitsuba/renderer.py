"""The ``mitsuba`` renderer object: Mitsuba 3 behind the harness's renderer protocol.

Per frame, the scene file is Mitsuba's (loaded once per variant; :mod:`.scenefile`), the camera is
the harness scene's at that frame (:mod:`.camera`) and animated objects are moved to their pose
(:mod:`.shapes`). Samples are taken as lanes of (pixel, sample index) with their own random
streams (:mod:`.streams`), so any range of samples renders the same bits anywhere: chunked and
resumable references, adaptive sampling that continues each pixel's stream, frames reproducible
per seed and frame. Sums are float64.
"""

from __future__ import annotations

import importlib.metadata
import os
import threading
from collections import OrderedDict

import numpy as np

from harness import Frame, FrameMeta, Scene, StreamRenderer, compute_threads

from . import camera, gbuffer, scenefile
from .shapes import Poser, match_objects, object_ids
from .streams import COLOR, VARIANCE, base_key
from .sums import PixelSums, lane_batches
from .variants import active, choose

OWNER = "renderer 'mitsuba'"
#: environment variable choosing the variant when the factory is given none
VARIANT_VARIABLE = "DENOISE_MITSUBA_VARIANT"
#: where the primary rays of reference samples go in their pixel
REFERENCE_PIXELS = ("area", "centre")
GBUFFER_CHANNELS = ("albedo", "normal", "depth", "position", "object_id", "motion", "emission")


class LoadedScene:
    """A scene file loaded with one variant and matched to the harness scene's objects.

    Attributes
    ----------
    engine : JitEngine or ScalarEngine
    poser : Poser
    ids : dict of str to int
        The object id of each shape of the file (distinct: :func:`.shapes.object_ids`).
    unmatched : int
        Shapes of the file that match no harness object (they get ids after the objects').
    """

    def __init__(self, mi, scene: Scene, max_depth: int, rr_depth: int):
        mi_scene, shape_ids = scenefile.load(mi, scenefile.scene_file(scene), scene.params.get("sunsky"))
        shapes = {s.id(): s for s in mi_scene.shapes()}
        matched = match_objects(shape_ids, scene)
        self.ids = ids = object_ids(mi_scene.shapes(), matched, len(scene.objects))
        self.unmatched = sum(1 for sid in shapes if matched.get(sid, -1) < 0)
        self.poser = Poser(mi, mi_scene, matched, scene.objects)
        integrator = mi.load_dict({"type": "path", "max_depth": int(max_depth), "rr_depth": int(rr_depth)})
        if mi.variant().startswith("scalar"):
            from .scalar import ScalarEngine

            self.engine = ScalarEngine(mi, mi_scene, integrator, ids)
        else:
            from .jit import JitEngine

            self.engine = JitEngine(mi, mi_scene, integrator, ids)


class FrameSetup:
    """One (scene, frame, resolution): its view and, once asked for, its G-buffer."""

    def __init__(self, scene: Scene, frame_index: int, width: int, height: int, loaded: LoadedScene):
        if scene.camera is None:
            raise ValueError(f"{OWNER}: scene {scene.name!r} has no camera")
        self.scene, self.index, self.width, self.height, self.loaded = scene, frame_index, width, height, loaded
        self.view = camera.view(scene.camera, frame_index, width, height)
        self._gbuffer = None

    def gbuffer(self) -> dict:
        if self._gbuffer is None:
            self.loaded.poser.pose(self.index)
            self._gbuffer = gbuffer.channels(self.loaded.engine.first_hits(self.view), self.view)
        return self._gbuffer


class MitsubaRenderer(StreamRenderer):
    """Mitsuba 3 renderer of scenes loaded from Mitsuba XML.

    Parameters
    ----------
    variant : {"auto", "cuda", "llvm", "scalar"} or None
        Mitsuba variant (:func:`.variants.choose`); ``auto`` takes ``cuda_ad_rgb`` on a working
        GPU, else ``llvm_ad_rgb`` where an LLVM works, else ``scalar_rgb`` with a warning. None
        (the default) reads :data:`VARIANT_VARIABLE` from the environment, ``auto`` without it (the
        command line's way to choose). The variant used is in :meth:`settings` (so in cache keys
        and the results).
    max_depth : int or None
        Longest path in segments (1: emitters seen directly, 2: direct lighting), Mitsuba's
        ``path`` integrator's meaning; None takes the scene's ``max_depth`` (as the path tracer).
    rr_depth : int
        Depth from which Russian roulette may end paths (Mitsuba's ``rr_depth``).
    variance_spp : int
        Pixels with fewer than 2 samples get the ``variance`` channel from this many extra,
        independent samples per pixel (which do not enter ``color``); 0 or 1: such pixels report
        0 (unknown), as the path tracer does.
    reference_pixel : {"area", "centre"}
        References (:meth:`accumulate`, :meth:`reference`) integrate over the pixel area (a box
        filter: each sample's primary ray through a uniform point of the pixel, as Mitsuba 3 and
        the path tracer's references) or take the pixel centre, as the noisy frames do.
    """

    owner = OWNER
    pixel_state = PixelSums

    def __init__(self, variant: str | None = None, max_depth: int | None = None, rr_depth: int = 5,
                 variance_spp: int = 8, reference_pixel: str = "area"):
        if max_depth is not None and int(max_depth) < 1:
            raise ValueError(f"{OWNER}: max_depth must be >= 1, got {max_depth}")
        if int(rr_depth) < 1:
            raise ValueError(f"{OWNER}: rr_depth must be >= 1, got {rr_depth}")
        if int(variance_spp) < 0:
            raise ValueError(f"{OWNER}: variance_spp must be >= 0, got {variance_spp}")
        if reference_pixel not in REFERENCE_PIXELS:
            raise ValueError(f"{OWNER}: reference_pixel must be one of {list(REFERENCE_PIXELS)}, got "
                             f"{reference_pixel!r}")
        self.variant = choose(variant or os.environ.get(VARIANT_VARIABLE) or "auto")
        self.max_depth = None if max_depth is None else int(max_depth)
        self.rr_depth = int(rr_depth)
        self.variance_spp = int(variance_spp)
        self.reference_pixel = reference_pixel
        self._loaded: OrderedDict = OrderedDict()
        self._setups: OrderedDict = OrderedDict()
        self._lock = threading.RLock()

    def settings(self) -> dict:
        """Settings that change images (part of cache keys), the variant and Mitsuba's version included."""
        return {"variant": self.variant, "max_depth": self.max_depth, "rr_depth": self.rr_depth,
                "variance_spp": self.variance_spp, "reference_pixel": self.reference_pixel,
                "mitsuba": importlib.metadata.version("mitsuba")}

    # -- preparation ---------------------------------------------------------------------------
    def _mitsuba(self):
        import mitsuba as mi

        return mi

    def _max_depth(self, scene: Scene) -> int:
        return self.max_depth if self.max_depth is not None else max(int(scene.max_depth), 1)

    def loaded(self, scene: Scene) -> LoadedScene:
        """The scene file loaded with this renderer's variant (two scenes kept)."""
        key = scene.content_hash()
        if key not in self._loaded:
            mi = self._mitsuba()
            with active(mi, self.variant):
                self._loaded[key] = LoadedScene(mi, scene, self._max_depth(scene), self.rr_depth)
            while len(self._loaded) > 2:
                self._loaded.popitem(last=False)
        self._loaded.move_to_end(key)
        return self._loaded[key]

    def setup(self, scene: Scene, frame_index: int, resolution=None) -> FrameSetup:
        """The view (and cached G-buffer) of a frame at a resolution."""
        if scene.kind != "mesh":
            raise ValueError(f"{OWNER}: renders mesh scenes only; {scene.name!r} is {scene.kind!r}")
        w, h = (int(v) for v in (resolution or scene.resolution))
        if w < 1 or h < 1:
            raise ValueError(f"{OWNER}: resolution must be positive, got {(w, h)}")
        key = (scene.content_hash(), frame_index, w, h)
        with self._lock:
            if key not in self._setups:
                self._setups[key] = FrameSetup(scene, frame_index, w, h, self.loaded(scene))
                while len(self._setups) > 2:
                    self._setups.popitem(last=False)
            self._setups.move_to_end(key)
            return self._setups[key]

    def add_samples(self, setup: FrameSetup, state: PixelSums, counts: np.ndarray, seed: int, *,
                    purpose: int = COLOR, squares: bool = True, area: bool = False) -> None:
        """Take ``counts[p]`` more samples in pixel ``p``, continuing its stream (in place); ``area``:
        primary rays uniform in the pixel rather than through its centre."""
        counts = np.ascontiguousarray(counts, np.int64).ravel()
        if counts.size and int(counts.min()) < 0:
            raise ValueError(f"{OWNER}: sample counts must be >= 0")
        mi = self._mitsuba()
        engine = setup.loaded.engine
        base = base_key(seed, setup.index, purpose)
        with self._lock, active(mi, self.variant):
            self._threads(mi)
            setup.loaded.poser.pose(setup.index)
            for pixels, samples in lane_batches(state.spp, counts, engine.max_lanes):
                state.add(pixels, engine.radiance(setup.view, pixels, samples, base, area), squares)
        state.spp += counts

    def _threads(self, mi) -> None:
        """Dr.Jit's CPU threads follow the harness's thread count (as the path tracer's Numba pool)."""
        if mi.variant().startswith("llvm"):
            import drjit as dr

            count = compute_threads()
            if dr.thread_count() != count:
                dr.set_thread_count(count)

    def variance(self, setup: FrameSetup, state: PixelSums, seed: int) -> np.ndarray:
        """Per-pixel variance of the mean of ``color`` (N, 3) float64.

        From the pixel's own samples where it has 2 or more (unbiased); else from the independent
        set of :attr:`variance_spp` samples (its per-sample variance over the pixel's samples, at
        least 1), taken once per frame and seed; else 0.
        """
        k = state.spp[:, None].astype(np.float64)
        mean = state.acc / np.maximum(k, 1.0)
        own = np.maximum(state.acc_sq - k * mean * mean, 0.0) / np.maximum(k * (k - 1.0), 1.0)
        few = state.spp < 2
        own[few] = 0.0
        if few.any() and self.variance_spp >= 2:
            if state.spread is None:
                extra = PixelSums(state.spp.shape[0])
                self.add_samples(setup, extra, np.full(extra.spp.shape, self.variance_spp, np.int64), seed,
                                 purpose=VARIANCE)
                n = float(self.variance_spp)
                m = extra.acc / n
                state.spread = np.maximum(extra.acc_sq - n * m * m, 0.0) / (n - 1.0)
            own[few] = state.spread[few] / np.maximum(k[few], 1.0)
        return own

    # -- frames --------------------------------------------------------------------------------
    def frame(self, setup: FrameSetup, state: PixelSums, seed: int, channels) -> Frame:
        """Assemble a :class:`harness.Frame` with ``channels`` (and ``color``) from the sums."""
        h, w = setup.height, setup.width
        n = np.maximum(state.spp, 1)[:, None].astype(np.float64)
        out = {"color": (state.acc / n).reshape(h, w, 3).astype(np.float32)}
        if "variance" in channels:
            out["variance"] = self.variance(setup, state, seed).reshape(h, w, 3).astype(np.float32)
        if "spp" in channels:
            out["spp"] = state.spp.reshape(h, w).astype(np.int32)
        wanted = [c for c in GBUFFER_CHANNELS if c in channels]
        if wanted:
            mi = self._mitsuba()
            with self._lock, active(mi, self.variant):
                g = setup.gbuffer()
            for name in wanted:
                if name == "motion":
                    out[name] = setup.scene.motion(g["position"], g["object_id"], setup.index, w, h)
                else:
                    out[name] = g[name]
        cam = setup.scene.camera
        meta = FrameMeta(
            index=setup.index,
            scene=setup.scene.name,
            seed=int(seed),
            view_proj=cam.view_projection(setup.index, w, h),
            prev_view_proj=cam.view_projection(max(setup.index - 1, 0), w, h),
            camera_cut=setup.index == 0,
            extra={"max_depth": self._max_depth(setup.scene), "samples": int(state.spp.sum()),
                   "variant": self.variant},
        )
        return Frame(out, meta, owner=OWNER)

    def render(self, scene: Scene, frame_index: int, *, spp: int = 1, seed: int = 0, channels=frozenset(),
               resolution=None) -> Frame:
        """A frame of ``spp`` samples per pixel with the requested channels (``color`` always)."""
        if int(spp) < 1:
            raise ValueError(f"{OWNER}: spp must be >= 1, got {spp}")
        channels = frozenset(channels)
        setup = self.setup(scene, frame_index, resolution)
        state = PixelSums(setup.width * setup.height)
        self.add_samples(setup, state, np.full(state.spp.shape, int(spp), np.int64), seed,
                         squares="variance" in channels)
        return self.frame(setup, state, seed, channels)

    def accumulate(self, scene: Scene, frame_index: int, *, first_sample: int, count: int, seed: int = 0,
                   resolution=None) -> np.ndarray:
        """Sum of the radiance of samples ``[first_sample, first_sample + count)`` per pixel, (H, W, 3) float64
        (the references' samples: over the pixel area unless ``reference_pixel="centre"``)."""
        if int(first_sample) < 0 or int(count) < 0:
            raise ValueError(f"{OWNER}: first_sample and count must be >= 0, got {first_sample}, {count}")
        setup = self.setup(scene, frame_index, resolution)
        state = PixelSums(setup.width * setup.height)
        state.spp[:] = int(first_sample)
        self.add_samples(setup, state, np.full(state.spp.shape, int(count), np.int64), seed, squares=False,
                         area=self.reference_pixel == "area")
        return state.acc.reshape(setup.height, setup.width, 3)

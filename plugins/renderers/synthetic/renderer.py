"""The ``synthetic`` renderer: analytic frames with exactly known clean image and noise."""

from __future__ import annotations

import numpy as np

from harness import Frame, FrameMeta, Sampler

from . import noise
from .pattern import Layout, gbuffer, motion

_GBUFFER = ("albedo", "normal", "depth", "position", "object_id", "motion", "visibility", "emission")


def _sample_sum(g: dict, seed: int, frame: int, first: int, count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sums of ``count[p]`` samples per pixel from sample index ``first``: (direct, indirect) float64."""
    h, w = count.shape
    flat = np.arange(h * w, dtype=np.uint64).reshape(h, w)
    sd = np.zeros((h, w))
    si = np.zeros((h, w))
    for k in range(int(count.max()) if count.size else 0):
        active = count > k
        ed = -np.log(noise.uniform(seed, frame, flat, first + k, 0))
        ei = -np.log(noise.uniform(seed, frame, flat, first + k, 1))
        sd += np.where(active, ed, 0.0)
        si += np.where(active, ei, 0.0)
    return g["direct"] * sd[..., None], g["indirect"] * si[..., None]


class SyntheticRenderer:
    """Renders ``procedural`` scenes of :mod:`.pattern`.

    Parameters
    ----------
    noise_scale : float
        Multiplies the per-sample deviation from the mean (1 = unit-mean exponential samples).
    """

    def __init__(self, noise_scale: float = 1.0):
        if noise_scale < 0:
            raise ValueError(f"synthetic renderer: noise_scale must be >= 0, got {noise_scale}")
        self.noise_scale = float(noise_scale)

    def settings(self) -> dict:
        return {"noise_scale": self.noise_scale}

    def _check(self, scene):
        if scene.kind != "procedural":
            raise ValueError(f"synthetic renderer renders procedural scenes only; {scene.name!r} is {scene.kind!r}")
        return Layout.from_params(scene.params)

    def _frame(self, scene, frame_index, g, spp_map, sums, seed, channels) -> Frame:
        layout = self._check(scene)
        h, w = spp_map.shape
        n = np.maximum(spp_map, 1)[..., None].astype(np.float64)
        mean_d = g["direct"] + self.noise_scale * (sums[0] / n - g["direct"])
        mean_i = g["indirect"] + self.noise_scale * (sums[1] / n - g["indirect"])
        out = {"color": (mean_d + mean_i + g["sky"]).astype(np.float32)}
        if "direct" in channels:
            out["direct"] = (mean_d + g["sky"]).astype(np.float32)
        if "indirect" in channels:
            out["indirect"] = mean_i.astype(np.float32)
        if "variance" in channels:
            var = self.noise_scale**2 * (g["direct"] ** 2 + g["indirect"] ** 2) / n
            out["variance"] = var.astype(np.float32)
        if "spp" in channels:
            out["spp"] = spp_map.astype(np.int32)
        for name in _GBUFFER:
            if name not in channels:
                continue
            if name == "object_id":
                out[name] = g["region"].astype(np.int32)
            elif name == "emission":  # no emitting surfaces (the sky is background)
                out[name] = np.zeros((h, w, 3), np.float32)
            elif name == "motion":
                out[name] = motion(layout, frame_index, w, h, g)
            else:
                out[name] = g[name].astype(np.float32)
        meta = FrameMeta(
            index=frame_index,
            scene=scene.name,
            seed=seed,
            camera_cut=frame_index == 0,
            extra={"samples": int(spp_map.sum())},
        )
        return Frame(out, meta, owner="renderer 'synthetic'")

    def render(
        self, scene, frame_index: int, *, spp: int = 1, seed: int = 0, channels=frozenset(), resolution=None
    ) -> Frame:
        """A noisy frame of ``spp`` samples per pixel with the requested channels."""
        layout = self._check(scene)
        if spp < 1:
            raise ValueError(f"synthetic renderer: spp must be >= 1, got {spp}")
        w, h = resolution or scene.resolution
        g = gbuffer(layout, frame_index, w, h)
        spp_map = np.full((h, w), spp, np.int32)
        sums = _sample_sum(g, seed, frame_index, 0, spp_map)
        return self._frame(scene, frame_index, g, spp_map, sums, seed, set(channels))

    def reference(self, scene, frame_index: int, *, spp: int = 0, seed: int = 0, resolution=None) -> np.ndarray:
        """The exact clean image (``spp`` is ignored: the expectation is known analytically)."""
        layout = self._check(scene)
        w, h = resolution or scene.resolution
        g = gbuffer(layout, frame_index, w, h)
        return (g["direct"] + g["indirect"] + g["sky"]).astype(np.float32)

    def accumulate(
        self, scene, frame_index: int, *, first_sample: int, count: int, seed: int = 0, resolution=None
    ) -> np.ndarray:
        """Sum of radiance of samples ``[first_sample, first_sample + count)`` per pixel, float64."""
        layout = self._check(scene)
        w, h = resolution or scene.resolution
        g = gbuffer(layout, frame_index, w, h)
        d, i = _sample_sum(g, seed, frame_index, first_sample, np.full((h, w), count, np.int32))
        dev = (d + i) - count * (g["direct"] + g["indirect"])
        return count * (g["direct"] + g["indirect"] + g["sky"]) + self.noise_scale * dev

    def sampler(
        self, scene, frame_index: int, *, spp: int = 1, seed: int = 0, channels=frozenset(), resolution=None
    ) -> Sampler:
        """An adaptive-sampling service starting from ``spp`` samples in every pixel."""
        return _SyntheticSampler(self, scene, frame_index, spp, seed, set(channels) | {"spp"}, resolution)


class _SyntheticSampler(Sampler):
    def __init__(self, renderer, scene, frame_index, spp, seed, channels, resolution):
        self._r, self._scene, self._index, self._seed, self._channels = renderer, scene, frame_index, seed, channels
        w, h = resolution or scene.resolution
        self._g = gbuffer(renderer._check(scene), frame_index, w, h)
        self._spp = np.full((h, w), spp, np.int32)
        self._sums = _sample_sum(self._g, seed, frame_index, 0, self._spp)
        super().__init__(renderer._frame(scene, frame_index, self._g, self._spp, self._sums, seed, channels))

    def _add(self, spp_map: np.ndarray) -> Frame:
        # continue every pixel's stream at its own next sample index
        h, w = spp_map.shape
        extra_d = np.zeros((h, w, 3))
        extra_i = np.zeros((h, w, 3))
        for start in np.unique(self._spp[spp_map > 0]):
            sel = (self._spp == start) & (spp_map > 0)
            d, i = _sample_sum(self._g, self._seed, self._index, int(start), np.where(sel, spp_map, 0))
            extra_d += d
            extra_i += i
        self._sums = (self._sums[0] + extra_d, self._sums[1] + extra_i)
        self._spp = self._spp + spp_map
        return self._r._frame(self._scene, self._index, self._g, self._spp, self._sums, self._seed, self._channels)

"""Adaptive sampling for filters such as SBF: more samples where the filter asks for them."""

from __future__ import annotations

import numpy as np

from harness import Frame, Sampler

from .sums import PixelSums

OWNER = "renderer 'mitsuba'"


class MitsubaSampler(Sampler):
    """Continues each pixel's sample stream on request.

    ``add_samples(spp_map)`` takes ``spp_map[i, j]`` more samples in pixel (i, j), with the sample
    indices that follow the pixel's last, so a pixel that got 8 and then 8 more samples holds the
    same samples as a 16-sample render (the same sums up to float64 rounding).
    :attr:`samples_used` counts every sample taken.

    Parameters
    ----------
    renderer : MitsubaRenderer
    scene : harness.Scene
    frame_index, spp, seed : int
    channels : iterable of str
        Channels of the frames returned (``color`` and ``spp`` always).
    resolution : (int, int) or None
    """

    def __init__(self, renderer, scene, frame_index: int, *, spp: int, seed: int, channels, resolution):
        if int(spp) < 1:
            raise ValueError(f"{OWNER}: sampler needs spp >= 1, got {spp}")
        self._renderer = renderer
        self._seed = int(seed)
        self._channels = frozenset(channels) | {"spp"}
        self._setup = renderer.setup(scene, frame_index, resolution)
        self._state = PixelSums(self._setup.width * self._setup.height)
        renderer.add_samples(self._setup, self._state, np.full(self._state.spp.shape, int(spp), np.int64),
                             self._seed)
        super().__init__(renderer.frame(self._setup, self._state, self._seed, self._channels))

    def _add(self, spp_map: np.ndarray) -> Frame:
        self._renderer.add_samples(self._setup, self._state, spp_map.astype(np.int64).ravel(), self._seed)
        return self._renderer.frame(self._setup, self._state, self._seed, self._channels)

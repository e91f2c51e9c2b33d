"""A base for renderers that keep per-pixel sample sums and continue each pixel's sample stream.

A subclass provides ``setup``, ``add_samples``, ``frame`` (the three steps of
:class:`harness.StreamSampler`) and ``accumulate`` (the chunked-renderer protocol); it gets
``reference`` (the mean of ``accumulate``) and ``sampler`` (a :class:`harness.StreamSampler`).
The path tracer and the ``mitsuba`` renderer are built on it.
"""

from __future__ import annotations

import numpy as np

from harness.sampling import StreamSampler


class StreamRenderer:
    """Mixin giving a stream renderer its ``reference`` and ``sampler`` methods.

    Attributes
    ----------
    owner : str
        Who is speaking in error messages (``"renderer 'NAME'"``).
    pixel_state : callable
        ``pixel_state(pixels)``: the renderer's empty per-pixel sums (what ``add_samples`` fills).
    """

    owner: str = "renderer"
    pixel_state = None

    def reference(self, scene, frame_index: int, *, spp: int = 4096, seed: int = 0, resolution=None) -> np.ndarray:
        """Converged image: ``accumulate(first_sample=0, count=spp) / spp`` as float32 (H, W, 3)."""
        if isinstance(spp, bool) or int(spp) < 1:
            raise ValueError(f"{self.owner}: spp must be >= 1, got {spp}")
        total = self.accumulate(scene, frame_index, first_sample=0, count=int(spp), seed=seed, resolution=resolution)
        return (np.asarray(total, np.float64) / float(spp)).astype(np.float32)

    def sampler(self, scene, frame_index: int, *, spp: int = 1, seed: int = 0, channels=frozenset(),
                resolution=None) -> StreamSampler:
        """An adaptive-sampling service starting with ``spp`` samples in every pixel."""
        return StreamSampler(self, scene, frame_index, spp=spp, seed=seed, channels=channels, resolution=resolution,
                             new_state=type(self).pixel_state, owner=self.owner)

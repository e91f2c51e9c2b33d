"""The adaptive-sampling service a renderer offers to adaptive filters.

:class:`Sampler` is the interface a filter sees; :class:`StreamSampler` implements it for
renderers that keep per-pixel sample sums and continue each pixel's sample stream (the path
tracer and the ``mitsuba`` renderer), so that a renderer plugin need not write its own.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Any

import numpy as np

from harness.buffers import Frame


class Sampler(ABC):
    """Hands an adaptive filter more samples in the pixels it chooses.

    A renderer that declares ``adaptive=True`` returns a subclass from its ``sampler(...)``
    method. The harness reads :attr:`samples_used` after the filter ran, so every result is
    honest about its sample budget.

    Parameters
    ----------
    frame : Frame
        The initial frame; must carry the ``spp`` channel.
    """

    def __init__(self, frame: Frame):
        if "spp" not in frame:
            raise ValueError("Sampler: the initial frame must carry the 'spp' channel")
        self._frame = frame
        self.samples_used = int(frame["spp"].astype(np.int64).sum())

    @property
    def frame(self) -> Frame:
        """The frame with every sample taken so far."""
        return self._frame

    def add_samples(self, spp_map: np.ndarray) -> Frame:
        """Take ``spp_map[i, j]`` more samples in pixel (i, j) and return the updated frame.

        Parameters
        ----------
        spp_map : ndarray (H, W), integer, >= 0

        Returns
        -------
        Frame
            Colour, variance and ``spp`` cover all samples taken so far; the sample streams
            continue those already taken.
        """
        spp_map = np.asarray(spp_map)
        want = self._frame.shape
        if spp_map.shape != want or spp_map.dtype.kind not in "iu":
            raise ValueError(
                f"Sampler.add_samples: expected integer array of shape {want}, got {spp_map.dtype} {spp_map.shape}"
            )
        if spp_map.size and int(spp_map.min()) < 0:
            raise ValueError("Sampler.add_samples: sample counts must be >= 0")
        spp_map = spp_map.astype(np.int32)
        self._frame = self._add(spp_map)
        self.samples_used += int(spp_map.astype(np.int64).sum())
        return self._frame

    @abstractmethod
    def _add(self, spp_map: np.ndarray) -> Frame:
        """Render the extra samples and return the merged frame."""


class StreamSampler(Sampler):
    """A :class:`Sampler` that continues each pixel's sample stream on request.

    ``add_samples(spp_map)`` takes ``spp_map[i, j]`` more samples in pixel (i, j) with the sample
    indices that follow the pixel's last, so a pixel that got 8 and then 8 more samples holds the
    samples of a 16-sample render. The renderer provides the three steps:

    - ``renderer.setup(scene, frame_index, resolution)``: the frame's view, with ``width`` and
      ``height`` attributes;
    - ``renderer.add_samples(setup, state, counts, seed)``: add ``counts[p]`` samples to pixel
      ``p``'s sums in ``state`` (flat, row-major);
    - ``renderer.frame(setup, state, seed, channels)``: the :class:`harness.Frame` of the sums.

    Parameters
    ----------
    renderer : object
        A renderer with the three methods above.
    scene : harness.Scene
    frame_index, spp, seed : int
        ``spp`` (>= 1) samples are taken in every pixel at the start.
    channels : iterable of str
        Channels of the frames returned (``color`` and ``spp`` always).
    resolution : (int, int) or None
    new_state : callable
        ``new_state(pixels)`` returns the renderer's empty per-pixel sums.
    owner : str
        Who is speaking in error messages (``"renderer 'NAME'"``).
    """

    def __init__(self, renderer: Any, scene: Any, frame_index: int, *, spp: int, seed: int, channels,
                 resolution, new_state: Callable[[int], Any], owner: str):
        if isinstance(spp, bool) or int(spp) < 1:
            raise ValueError(f"{owner}: sampler needs spp >= 1, got {spp}")
        self._renderer = renderer
        self._seed = int(seed)
        self._channels = frozenset(channels) | {"spp"}
        self._setup = renderer.setup(scene, frame_index, resolution)
        self._state = new_state(self._setup.width * self._setup.height)
        self._renderer.add_samples(self._setup, self._state,
                                   np.full(self._setup.width * self._setup.height, int(spp), np.int64), self._seed)
        super().__init__(self._renderer.frame(self._setup, self._state, self._seed, self._channels))

    def _add(self, spp_map: np.ndarray) -> Frame:
        self._renderer.add_samples(self._setup, self._state, spp_map.astype(np.int64).ravel(), self._seed)
        return self._renderer.frame(self._setup, self._state, self._seed, self._channels)

"""The adaptive-sampling service a renderer offers to adaptive filters."""

from __future__ import annotations

from abc import ABC, abstractmethod

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

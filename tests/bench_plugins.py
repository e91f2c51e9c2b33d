"""Filters for the bench's tests, loaded by the ``local`` executor's worker by module name.

``alloc_frames`` allocates (and writes) ten full float32 RGB frames in every call, then returns
a copy of the colour: its peak memory per call is eleven frames. ``threads_probe`` returns the
colour and fails when :func:`harness.compute_threads` disagrees with Numba's thread count; it
reports two stages, one named ``filter`` like the table's key column (as ``sbf`` does).
"""

import numba
import numpy as np

from harness import FilterSpec, compute_threads, hookimpl

#: full frames ``alloc_frames`` holds at once (besides its output)
FRAMES = 10


class AllocFrames:
    def __init__(self, backend="cpu"):
        pass

    def reset(self):
        pass

    def __call__(self, frame, sampler=None):
        held = [np.ones(frame["color"].shape, np.float32) for _ in range(FRAMES)]
        out = np.array(frame["color"], np.float32)
        out[0, 0, 0] += np.float32(0.0) * held[-1][0, 0, 0]
        return out


class ThreadsProbe(AllocFrames):
    def __call__(self, frame, sampler=None):
        if compute_threads() != numba.get_num_threads():
            raise RuntimeError("compute_threads() disagrees with numba.get_num_threads()")
        self.stage_ms = {"filter": 1.5, "copy": 0.5}
        return np.array(frame["color"], np.float32)


@hookimpl
def register_filters():
    return [FilterSpec(name="alloc_frames", version="0", factory=AllocFrames, requires={"color", "normal"}),
            FilterSpec(name="threads_probe", version="0", factory=ThreadsProbe,
                       stage_timing=True)]

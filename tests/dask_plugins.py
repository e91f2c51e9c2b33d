"""Filters for the Dask executor's tests, loaded by the workers by module name.

``slow`` sleeps in every call (so a worker can be killed while it holds the job); ``exits`` ends
its worker process (``os._exit``) on every call.
"""

import os
import time

import numpy as np

from harness import FilterSpec, hookimpl


class Slow:
    def __init__(self, backend="cpu", how="slow"):
        self.how = how

    def reset(self):
        pass

    def __call__(self, frame, sampler=None):
        if self.how == "exits":
            os._exit(9)
        time.sleep(0.15)
        return np.ascontiguousarray(frame["color"] * np.float32(0.5) + np.float32(0.25))


@hookimpl
def register_filters():
    return [FilterSpec(name=how, version="0", factory=lambda backend="cpu", how=how: Slow(backend, how))
            for how in ("slow", "exits")]

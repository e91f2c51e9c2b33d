"""Peak memory of a piece of work, measured in the process that runs it.

Two measures, taken around one call of ``work`` (:func:`peak_memory`), or between the two ends of
a :class:`MemoryWatch` where the work is not one call (the ``rss`` one alone, cheaper, with
:func:`rss_mark` before the work and :func:`rss_rise` after it):

``traced``
    the peak of the bytes allocated through Python's allocators during the call, above what
    was allocated before it (:mod:`tracemalloc`). NumPy registers its array buffers with
    tracemalloc, so this counts every NumPy array the work creates and Python objects; arrays
    Numba's runtime allocates in compiled code were traced too (measured with Numba 0.68:
    ten frames allocated in an ``@njit`` function count as ten frames). Native libraries' own
    allocations (OpenCV, OIDN, PyTorch's CPU allocator) are not traced.
``rss``
    the rise of the process's resident set size high-water mark (``VmHWM``) over its resident
    size before the call, on Linux: free heap memory is first handed back to the system
    (``malloc_trim``) and the high-water mark reset (``/proc/self/clear_refs``), so every
    page the call touches that was not in use before counts, whoever allocated it. Pages
    allocated but never written are not counted (they use no memory). It includes
    tracemalloc's own bookkeeping (small: about 100 bytes per live traced allocation). Where
    the mark cannot be reset (another system, a kernel without ``clear_refs``) it is NaN.

Neither counts memory the work allocated before the call and still holds (a filter's buffers
kept from an earlier frame) or that was freed by the allocator but kept in the process and
reused; the larger of the two is a lower bound of the call's true peak and close to it where
the work's memory comes from one allocator.
"""

from __future__ import annotations

import ctypes
import gc
import math
import tracemalloc
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

_STATUS = Path("/proc/self/status")
_CLEAR_REFS = Path("/proc/self/clear_refs")


@dataclass(frozen=True)
class MemoryPeak:
    """Bytes above the level before the call (see the module docstring).

    Attributes
    ----------
    traced : int
        Peak of tracemalloc-traced bytes during the call.
    rss : float
        Rise of the resident set size's high-water mark (NaN where it cannot be measured).
    """

    traced: int
    rss: float

    @property
    def peak(self) -> float:
        """The larger of the two (bytes)."""
        return float(max(self.traced, self.rss)) if not math.isnan(self.rss) else float(self.traced)


def _status_kb(field: str) -> float:
    try:
        for line in _STATUS.read_text().splitlines():
            if line.startswith(field + ":"):
                return float(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return math.nan


def _trim() -> None:
    """Return free heap memory to the system (glibc ``malloc_trim``; nothing elsewhere)."""
    try:
        ctypes.CDLL(None).malloc_trim(0)
    except (OSError, AttributeError):
        pass


def rss_mark() -> float:
    """Reset the resident set size's high-water mark (``VmHWM``) to the current resident size.

    Returns
    -------
    float
        That size in bytes, NaN where the mark cannot be reset (not Linux >= 4.0); pass it to
        :func:`rss_rise`.
    """
    try:
        _CLEAR_REFS.write_text("5")
    except OSError:
        return math.nan
    if math.isnan(_status_kb("VmHWM")):
        return math.nan
    return _status_kb("VmRSS") * 1024.0


def rss_rise(mark: float) -> float:
    """Bytes by which the high-water mark rose above ``mark`` (from :func:`rss_mark`), at least 0;
    NaN where ``mark`` is."""
    if math.isnan(mark):
        return math.nan
    return max(_status_kb("VmHWM") * 1024.0 - mark, 0.0)


class MemoryWatch:
    """The two measures of the module between :meth:`start` and :meth:`stop`.

    Parameters
    ----------
    traced : bool
        Take tracemalloc's peak too (started for the span where it is not already tracing, and
        stopped again after it); the resident set size's rise alone otherwise.
    """

    def __init__(self, traced: bool = True):
        self.traced = traced
        self._mark = math.nan
        self._start = 0
        self._was_tracing = True

    def start(self, resident: bool = True) -> None:
        """Reset the marks; ``resident=False`` skips the resident set size (its rise is then NaN)."""
        self._mark = rss_mark() if resident else math.nan
        if self.traced:
            self._was_tracing = tracemalloc.is_tracing()
            if not self._was_tracing:
                tracemalloc.start()
            tracemalloc.reset_peak()
            self._start = tracemalloc.get_traced_memory()[0]

    def stop(self) -> MemoryPeak:
        """The peaks since :meth:`start` (``traced`` is 0 when not traced)."""
        traced = 0
        if self.traced:
            traced = max(tracemalloc.get_traced_memory()[1] - self._start, 0)
            if not self._was_tracing:
                tracemalloc.stop()
        return MemoryPeak(traced=int(traced), rss=rss_rise(self._mark))


def peak_memory(work: Callable[[], Any]) -> tuple[Any, MemoryPeak]:
    """Call ``work()`` once and measure its peak memory.

    Returns
    -------
    result : any
        What ``work`` returned.
    peak : MemoryPeak
    """
    gc.collect()
    _trim()
    watch = MemoryWatch()
    watch.start()
    try:
        result = work()
    finally:
        peak = watch.stop()
    return result, peak


__all__ = ["MemoryPeak", "MemoryWatch", "peak_memory", "rss_mark", "rss_rise"]

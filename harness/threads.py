"""How many threads a filter may use, set where its job runs (``denoise-bench bench --threads``).

One number rules every thread pool a filter can reach: Numba's (``numba.set_num_threads``,
which Numba keeps per calling thread), OpenCV's (``cv2.setNumThreads``) and PyTorch's
intra-op pool (``torch.set_num_threads``), the last two only where a plugin has already
imported them (the core imports neither). A library whose thread count is a property of an
object it builds (OIDN's ``numThreads`` device parameter) reads :func:`compute_threads` when
the plugin builds that object. :func:`using_threads` applies a count for the duration of a
task in the worker process and restores the previous counts afterwards.
:func:`thread_cpu_seconds` and :func:`balance` say how the work of a call was shared among
the process's threads (``denoise-bench bench --balance``).
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Iterator, Mapping
from contextlib import contextmanager


def max_threads() -> int:
    """The most threads Numba can use in this process (``NUMBA_NUM_THREADS``, the core count by default)."""
    import numba

    return int(numba.config.NUMBA_NUM_THREADS)


def compute_threads() -> int:
    """The number of threads filters should use for their own thread pools.

    The Numba thread count of the calling thread: all cores unless a bench (``--threads``) or
    the user (``numba.set_num_threads``) lowered it. A plugin whose library takes its thread
    count as a setting of an object (e.g. an OIDN device's ``numThreads``) passes this value
    when it builds that object.
    """
    import numba

    return int(numba.get_num_threads())


def _set(count: int) -> dict:
    """Set every known pool to ``count``; return the previous counts."""
    import numba

    previous = {"numba": numba.get_num_threads()}
    numba.set_num_threads(count)
    cv2 = sys.modules.get("cv2")
    if cv2 is not None and hasattr(cv2, "setNumThreads"):
        previous["cv2"] = cv2.getNumThreads()
        cv2.setNumThreads(count)
    torch = sys.modules.get("torch")
    if torch is not None and hasattr(torch, "set_num_threads"):
        previous["torch"] = torch.get_num_threads()
        torch.set_num_threads(count)
    return previous


def _restore(previous: dict) -> None:
    import numba

    numba.set_num_threads(previous["numba"])
    if "cv2" in previous:
        sys.modules["cv2"].setNumThreads(previous["cv2"])
    if "torch" in previous:
        sys.modules["torch"].set_num_threads(previous["torch"])


@contextmanager
def using_threads(count: int | None) -> Iterator[int]:
    """Run the body with ``count`` threads in every pool (None: leave the counts as they are).

    Parameters
    ----------
    count : int or None
        In [1, :func:`max_threads`].

    Yields
    ------
    int
        The Numba thread count in effect.

    Raises
    ------
    ValueError
        For a count outside [1, :func:`max_threads`].
    """
    if count is None:
        yield compute_threads()
        return
    if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= max_threads():
        raise ValueError(f"threads must be an integer in [1, {max_threads()}] here, got {count!r}")
    previous = _set(count)
    try:
        yield compute_threads()
    finally:
        _restore(previous)


def thread_cpu_seconds() -> dict[str, float]:
    """CPU seconds (user + system) of each thread of this process, by thread id.

    Read from ``/proc/self/task/*/stat`` (Linux; clock ticks, usually 10 ms): an empty dict
    elsewhere. A thread that ends while it is read is left out.
    """
    try:
        tick = os.sysconf("SC_CLK_TCK")
        tids = os.listdir("/proc/self/task")
    except (OSError, ValueError, AttributeError):
        return {}
    times = {}
    for tid in tids:
        try:
            with open(f"/proc/self/task/{tid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            times[tid] = (int(fields[11]) + int(fields[12])) / tick  # utime, stime (fields 14, 15)
        except (OSError, IndexError, ValueError):
            continue
    return times


def balance(spent: Mapping[str, float]) -> tuple[float, float]:
    """How evenly work was shared, from each thread's CPU seconds (differences of :func:`thread_cpu_seconds`).

    Returns
    -------
    busiest_share : float
        The busiest thread's share of the total (1 / threads when shared evenly, 1 when one
        thread did everything).
    spread : float
        Total / busiest: the speed-up over one thread that this sharing allows on otherwise
        idle cores. NaN (both) when no CPU time was recorded.
    """
    busy = [t for t in spent.values() if t > 0]
    if not busy:
        return math.nan, math.nan
    total, top = sum(busy), max(busy)
    return top / total, total / top


__all__ = ["balance", "compute_threads", "max_threads", "thread_cpu_seconds", "using_threads"]

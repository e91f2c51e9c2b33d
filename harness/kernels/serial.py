"""Run a small image's parallel loops on one thread.

Each parallel region waits for the pool's threads to be scheduled, which on a loaded 2-core
machine costs more than the second thread saves on a small image: every region of ``eaw``
waited 4-8 ms (a 192x108 frame took 80 ms on two threads, 2.5 ms on one), a 320x180 frame of
``svgf`` took 374 ms on two threads and 66 ms on one (see their READMEs).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from numba import get_num_threads, set_num_threads

#: images below this many pixels run on one thread (:func:`serial_below`)
SERIAL_MAX_PIXELS = 256 * 256


@contextmanager
def serial_below(pixels: int, limit: int = SERIAL_MAX_PIXELS, *, enabled: bool = True) -> Iterator[bool]:
    """Within the block, Numba runs on one thread if ``pixels < limit``; the count is restored after.

    Parameters
    ----------
    pixels : int
        The image's size (height times width).
    limit : int
        The smallest image that keeps every thread.
    enabled : bool
        False leaves the threads alone (a backend without Numba's CPU threads, e.g. ``cuda``).

    Yields
    ------
    bool
        Whether the block runs serially.
    """
    threads = get_num_threads()
    serial = enabled and pixels < limit and threads > 1
    if serial:
        set_num_threads(1)
    try:
        yield serial
    finally:
        if serial:
            set_num_threads(threads)

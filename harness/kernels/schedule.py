"""Dynamic load balancing of parallel loops: ranges of work taken from a shared atomic counter.

Numba's threading layers hand each thread one contiguous block of a ``prange`` (even under
``numba.parallel_chunksize``), so an image split into rows gives one thread the sky at the top
and the other the detailed bottom, whatever their cost, and a thread that shares its core with
another process holds the whole loop up. A balanced loop therefore runs one ``prange`` iteration
per thread, and each thread takes the next range of work from a counter until none is left:
the threads walk through the image together, in order (their neighbouring rows share the
cache), and finish within one range of each other. The loop: a zero int64 array ``counter`` of
one element; ``prange(thread_count(threads, n, size))``; in each iteration, ``start, stop =
take_range(counter, n, size)`` until ``start >= stop``, doing items ``start .. stop - 1`` (the
``cpu`` backend of ``svgf`` is an example).

Which thread takes which range must not change any result: each item is computed on its own.
"""

from __future__ import annotations

from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic


@intrinsic
def take(typingctx, counter):
    """Atomically add 1 to ``counter[0]`` and return its previous value.

    Parameters
    ----------
    counter : int64 array
        Shared by the threads; zero before the loop.

    Returns
    -------
    int64

    Notes
    -----
    Numba does not know that this writes ``counter``: read ``counter[0]`` only through
    :func:`take` (in the function that owns the counter, ``counter[0]`` read after the parallel
    loop may give the value from before it).
    """
    if not (isinstance(counter, types.Array) and counter.dtype == types.int64):
        return None

    def codegen(context, builder, signature, args):
        array = context.make_array(signature.args[0])(context, builder, args[0])
        return builder.atomic_rmw("add", array.data, ir.Constant(ir.IntType(64), 1), "monotonic")

    return types.int64(counter), codegen


@njit(inline="always")
def take_range(counter, n, size):
    """The next range of ``size`` consecutive items of ``0 .. n - 1`` (the last one shorter).

    Parameters
    ----------
    counter : int64 array
        The shared counter (see :func:`take`).
    n : int
        Items in all.
    size : int
        Items per range.

    Returns
    -------
    start, stop : int
        ``range(start, stop)``; ``start >= stop`` once every range is taken.
    """
    start = take(counter) * size
    return start, min(start + size, n)


@njit(inline="always")
def thread_count(threads, n, size):
    """``prange`` iterations of a loop over :func:`take_range`: ``threads``, at most one per
    range and at least 1.

    Parameters
    ----------
    threads : int
        The threads to use (``numba.get_num_threads()``).
    n, size : int
        As for :func:`take_range`.

    Returns
    -------
    int
    """
    return max(min(threads, -(-n // size)), 1)
